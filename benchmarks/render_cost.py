"""What a render costs beyond tracing its rays: ``python -m benchmarks.render_cost``.

A 512x512 lambert render with shadows and 4 samples a pixel (the issue's bar), of the service's
demo scene and of the shared stanford-bunny, shaded smooth, from the camera as the service
renders (``raycore.render.render_camera``).  Tracing is timed on the very rays the render
traces, each set in one call: its camera rays' closest hits (no surface fields) and its shadow
rays, captured from a render (which traces them a band of rows at a time).  Everything else
(ray generation, surface fields and shading normals, shadow-ray set-up, shading, the
linear-light mean of the samples, sRGB encoding) is the render's own cost.  Render and tracing
are timed in interleaved rounds, best of each; writes ``benchmarks/results/render_cost.json``.
"""

import argparse
import json
import os
from pathlib import Path

import numpy as np

from benchmarks.meshes import load
from benchmarks.timing import interleaved_best_times
from raycore import Scene
from raycore.camera import frame_box, perspective_camera
from raycore.render import render_camera
from service.builder import build_scene
from service.demo import DEMO_CAMERA, demo_spec

RESULTS = Path(__file__).resolve().parent / "results" / "render_cost.json"
SIZE, SAMPLES = 512, 4


class _ShadowRays:
    """``scene`` whose ``occluded`` keeps the rays of every call: a render traces its shadow
    rays a band at a time (``raycore.render.TILE_RAYS``)."""

    def __init__(self, scene):
        self.scene, self.calls = scene, []

    def __getattr__(self, name):
        return getattr(self.scene, name)

    def __len__(self):
        return len(self.scene)

    def occluded(self, origins, directions, **options):
        # copies: the render writes each band's shadow rays over the last band's
        self.calls.append((origins.copy(), directions.copy(), options))
        return self.scene.occluded(origins, directions, **options)

    def shadow_rays(self):
        """The shadow rays of every call, as one batch: ``(origins, directions), options``."""
        origins, directions, options = zip(*self.calls, strict=True)
        assert all(option == options[0] for option in options)
        return (np.concatenate(origins), np.concatenate(directions)), options[0]


def measure(name, scene, colors, position, look_at, rounds):
    """Best render and tracing times of one scene, and their ratio."""
    camera = perspective_camera(position, look_at, (0.0, 1.0, 0.0), 45.0, SIZE, SIZE)
    origins, directions = camera.rays(scene.dtype, SAMPLES)
    captured = _ShadowRays(scene)
    render_camera(captured, camera, samples=SAMPLES, colors=colors)
    shadow_args, shadow_options = captured.shadow_rays()

    def full_render():
        # from the camera, as the service renders: its rays are made in the timed call
        camera = perspective_camera(position, look_at, (0.0, 1.0, 0.0), 45.0, SIZE, SIZE)
        return render_camera(scene, camera, samples=SAMPLES, colors=colors)

    def tracing():
        scene.intersect(origins, directions)
        return scene.occluded(*shadow_args, **shadow_options)

    def tracing_with_normals():
        scene.intersect(origins, directions, fields=("normal",))
        return scene.occluded(*shadow_args, **shadow_options)

    best, _ = interleaved_best_times({"render": full_render, "tracing": tracing,
                                      "tracing_with_normals": tracing_with_normals}, rounds)
    hit = float(np.mean(scene.intersect(origins, directions).hit))
    lit = len(shadow_args[0]) / len(origins)  # a shadow ray per lit hit
    return {"scene": name, "size": f"{SIZE}x{SIZE}", "samples": SAMPLES,
            "rays": len(origins), "hit_fraction": round(hit, 3),
            "shadow_rays_traced_fraction": round(lit, 3),
            "render_s": round(best["render"], 4), "tracing_s": round(best["tracing"], 4),
            "tracing_with_normals_s": round(best["tracing_with_normals"], 4),
            "render_over_tracing": round(best["render"] / best["tracing"], 3),
            "overhead_over_tracing": round(best["render"] / best["tracing"] - 1, 3),
            "overhead_over_tracing_with_normals": round(
                best["render"] / best["tracing_with_normals"] - 1, 3)}


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rounds", type=int, default=5)
    args = parser.parse_args(argv)
    entry, _ = build_scene(demo_spec(), lambda mesh: None, 10**8, 10**8)
    rows = [measure("demo", entry.scene, entry.colors, DEMO_CAMERA["position"],
                    DEMO_CAMERA["look_at"], args.rounds)]
    bunny = Scene("float32")
    bunny.add_mesh(*load("stanford-bunny"))
    position, look_at, _ = frame_box(*bunny.bounds, SIZE, SIZE)
    rows.append(measure("stanford-bunny", bunny, None, position, look_at, args.rounds))
    for row in rows:
        print(f"{row['scene']}: render {row['render_s'] * 1000:.0f} ms, tracing "
              f"{row['tracing_s'] * 1000:.0f} ms ({row['tracing_with_normals_s'] * 1000:.0f} ms "
              f"with normals): render / tracing {row['render_over_tracing']}, the render's own "
              f"cost {row['overhead_over_tracing']}x tracing "
              f"({row['overhead_over_tracing_with_normals']}x with normals)")
    RESULTS.write_text(json.dumps({"threads": os.cpu_count(), "rows": rows}, indent=2) + "\n")


if __name__ == "__main__":
    main()
