"""``raycore render``: framed pictures of mesh files, and scene JSON rendered as the service
renders it."""

import io
import json
import shutil

import numpy as np
import pytest
from PIL import Image

from raycore.cli import main
from tests.commands.conftest import mesh_file, refused


def _picture(path):
    with Image.open(path) as image:
        assert image.format == "PNG"
        return np.asarray(image.convert("RGB"))


def test_bunny_with_no_other_argument_is_framed_and_shaded(tmp_path):
    out = tmp_path / "bunny.png"
    main(["render", str(mesh_file("stanford-bunny")), "-o", str(out)])
    image = _picture(out)
    assert image.shape == (512, 512, 3)  # the default size
    mesh = image.any(axis=2)  # background is black
    centre = mesh[224:288, 224:288]
    assert centre.mean() > 0.9
    # framed: the whole mesh is in the picture, and it fills a good part of it
    assert not (mesh[0].any() or mesh[-1].any() or mesh[:, 0].any() or mesh[:, -1].any())
    rows, columns = np.flatnonzero(mesh.any(axis=1)), np.flatnonzero(mesh.any(axis=0))
    assert max(rows[-1] - rows[0], columns[-1] - columns[0]) > 0.6 * 512
    # shaded: lit and shadowed parts, not one flat colour
    grey = image[mesh].mean(axis=1)
    # (sRGB: the ambient light alone, 0.15 of the grey albedo 0.8, is 108)
    assert len(np.unique(grey)) > 50 and grey.min() < 115 and grey.max() > 160


def test_orthographic_normal_shading_frames_too(tmp_path):
    out = tmp_path / "suzanne.png"
    main(["render", str(mesh_file("suzanne")), "-o", str(out), "--camera", "orthographic",
          "--shading", "normal", "--width", "96", "--height", "64"])
    image = _picture(out)
    assert image.shape == (64, 96, 3)
    mesh = image.any(axis=2)
    assert mesh[24:40, 40:56].mean() > 0.8
    assert not (mesh[0].any() or mesh[-1].any() or mesh[:, 0].any() or mesh[:, -1].any())
    assert len(np.unique(image[mesh], axis=0)) > 20  # normals vary over the surface


def test_scene_json_renders_as_the_service_renders_it(tmp_path):
    from fastapi.testclient import TestClient

    from service.app import create_app
    from service.config import Settings

    (tmp_path / "parts").mkdir()
    shutil.copy(mesh_file("suzanne"), tmp_path / "parts" / "monkey.obj")
    objects = [{"type": "plane", "point": [0, -1, 0], "normal": [0, 1, 0]},
               {"type": "mesh", "mesh": "parts/monkey.obj",
                "material": {"color": [0.9, 0.3, 0.2]}},
               {"type": "instance", "mesh": 1,
                "transform": [[1, 0, 0, 3], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]]},
               {"type": "sphere", "center": [-2.5, 0.5, 4], "radius": 1}]
    (tmp_path / "scene.json").write_text(json.dumps({"dtype": "float64", "objects": objects}))
    camera = {"position": [1.0, 6.0, 14.0], "look_at": [-1.0, 0.5, 4.0], "fov": 50.0}
    out = tmp_path / "scene.png"
    main(["render", str(tmp_path / "scene.json"), "-o", str(out), "--width", "80", "--height",
          "60", "--position", *map(str, camera["position"]), "--look-at",
          *map(str, camera["look_at"]), "--fov", "50"])

    with TestClient(create_app(Settings(demo=False))) as client:
        upload = client.post("/v1/meshes?format=obj",
                             content=(tmp_path / "parts" / "monkey.obj").read_bytes())
        objects[1]["mesh"] = upload.json()["id"]
        scene = client.post("/v1/scenes", json={"dtype": "float64", "objects": objects}).json()
        # samples: 4, the command's default
        served = client.post(f"/v1/scenes/{scene['id']}/render", json={"camera": {
            "type": "perspective", **camera, "width": 80, "height": 60}, "samples": 4})
    assert served.status_code == 200
    expected = np.asarray(Image.open(io.BytesIO(served.content)).convert("RGB"))
    image = _picture(out)
    np.testing.assert_array_equal(image, expected)
    # every object shows: the floor, the red monkey, the grey one, the sphere
    assert (image[..., 0] > 2 * image[..., 2] + 20).sum() > 50  # red
    assert len(np.unique(image.reshape(-1, 3), axis=0)) > 50


@pytest.mark.parametrize("argv, message", [
    (["--fov", "200"], "--fov must be in (0, 180) degrees"),
    (["--position", "1", "2", "3", "--look-at", "1", "2", "3"], "--look-at must differ"),
    (["--position", "0", "5", "0", "--look-at", "0", "0", "0"], "--up must not be parallel"),
    (["--up", "0", "0", "0"], "--up must not be zero"),
])
def test_bad_camera_options_are_named(tmp_path, capsys, argv, message):
    code, err = refused(["render", mesh_file("suzanne"), "-o", tmp_path / "x.png", *argv],
                        capsys)
    assert code == 1 and message in err and err.count("\n") <= 1
    assert not (tmp_path / "x.png").exists()


def test_negative_numbers_in_exponent_form_are_values(tmp_path):
    """``--position 0 0 -4e0`` is a position, not an option (Python 3.11's argparse read -4e0 as
    one)."""
    pictures = []
    for z in ("-4", "-4e0"):
        out = tmp_path / f"{z}.png"
        main(["render", str(mesh_file("suzanne")), "-o", str(out), "--width", "24", "--height",
              "24", "--position", "0", "0", z, "--look-at", "0", "0", "0"])
        pictures.append(_picture(out))
    np.testing.assert_array_equal(*pictures)
    assert pictures[0].any()


def test_bad_scene_json_is_one_line(tmp_path, capsys):
    scene = tmp_path / "scene.json"
    scene.write_text(json.dumps({"objects": [{"type": "sphere", "center": [0, 0, 0],
                                              "radius": -1}]}))
    code, err = refused(["render", scene, "-o", tmp_path / "x.png"], capsys)
    assert code == 1
    assert err.strip() == (f"raycore render: {scene}: objects.0.sphere.radius: Input should be "
                           "greater than 0")
    scene.write_text(json.dumps({"objects": [{"type": "mesh", "mesh": "gone.obj"}]}))
    code, err = refused(["render", scene, "-o", tmp_path / "x.png"], capsys)
    assert code == 1
    assert err.strip() == (f"raycore render: {scene}: objects[0].mesh: {tmp_path / 'gone.obj'}: "
                           "no such file")
