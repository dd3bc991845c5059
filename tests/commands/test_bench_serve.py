"""``raycore bench`` runs benchmarks/run.py with its own options; ``raycore serve --workers``."""

import pytest

from raycore import cli
from raycore.commands import bench
from tests.commands.conftest import refused


def _options(parser):
    return {option for action in parser._actions for option in action.option_strings}


def _subparser(name):
    commands = next(action for action in cli.build_parser()._actions
                    if hasattr(action, "choices") and isinstance(action.choices, dict))
    return commands.choices[name]


def test_bench_offers_the_benchmarks_options():
    from benchmarks import run

    hidden = {"--variant-output"}  # its own subprocesses'
    assert _options(_subparser("bench")) == _options(run.parser()) - hidden


def test_bench_passes_its_options_and_progress_on(monkeypatch):
    from benchmarks import run

    calls = []
    monkeypatch.setattr(bench, "NEEDS", ())
    monkeypatch.setattr(run, "main", lambda argv, progress: calls.append((argv, progress)))
    # the subdivided meshes' names, which a checkout without ../shared/meshes knows too
    cli.main(["bench", "--quick", "--rounds", "2", "--meshes", "nefertiti-1.6M",
              "nefertiti-6.4M"])
    (argv, progress), = calls
    assert argv == ["--quick", "--rounds", "2", "--meshes", "nefertiti-1.6M", "nefertiti-6.4M"]
    with progress("meshes", total=2) as advance:  # not a terminal here: quiet, but usable
        advance()
    assert run.parser().parse_args(argv).rounds == 2


def test_bench_without_its_extra_says_so(monkeypatch, capsys):
    monkeypatch.setattr(bench, "NEEDS", ("raycore_no_such_module",))
    code, err = refused(["bench", "--quick"], capsys)
    assert code == 1
    assert err.strip() == ("raycore bench: the benchmark needs the bench extra "
                           "(raycore_no_such_module missing): pip install -e '.[service,bench]' "
                           "(or make bench)")


def test_bench_names_unknown_meshes(monkeypatch, capsys):
    monkeypatch.setattr(bench, "NEEDS", ())
    code, err = refused(["bench", "--meshes", "nefertiti-1.6M", "armadillo"], capsys)
    assert code == 1 and err.startswith("raycore bench: --meshes: no mesh named armadillo (")


@pytest.mark.parametrize("argv, workers", [([], None), (["--workers", "3"], 3)])
def test_serve_workers(monkeypatch, argv, workers):
    import uvicorn

    calls = []
    monkeypatch.setattr(uvicorn, "run", lambda app, **options: calls.append((app, options)))
    cli.main(["serve", "--port", "8123", *argv])
    (app, options), = calls
    # worker processes make their own app from its import name
    assert app == "service.app:create_app" and options["factory"] is True
    assert options["workers"] == workers and options["port"] == 8123


def test_serve_refuses_zero_workers(capsys):
    code, err = refused(["serve", "--workers", "0"], capsys)
    assert code == 2
    assert err.strip() == ("raycore serve: error: argument --workers: must be a positive "
                           "integer, got '0' (see raycore serve --help)")
