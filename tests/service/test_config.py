"""Settings from the environment."""

import pytest

from service.config import Settings, load_settings


def test_defaults_and_overrides():
    assert load_settings({}) == Settings()
    settings = load_settings({"RAYCORE_MAX_RAYS": "10", "RAYCORE_DEMO": "false", "HOME": "/"})
    assert settings.max_rays == 10 and settings.demo is False


@pytest.mark.parametrize(("name", "value"), [
    ("RAYCORE_MAX_RAYS", "ten"), ("RAYCORE_STORE_BYTES", "0"), ("RAYCORE_MAX_RAYS", "-5"),
    ("RAYCORE_DEMO", "maybe"),
])
def test_bad_values_name_the_variable(name, value):
    with pytest.raises(ValueError, match=name):
        load_settings({name: value})


def test_body_deadline_from_the_environment():
    assert load_settings({"RAYCORE_BODY_SECONDS": "5"}).body_seconds == 5
    with pytest.raises(ValueError, match="RAYCORE_BODY_SECONDS"):
        load_settings({"RAYCORE_BODY_SECONDS": "0"})


def test_data_directory_settings():
    settings = load_settings({"RAYCORE_DATA_DIR": "/var/lib/raycore",
                              "RAYCORE_DATA_BYTES": "1000"})
    assert settings.data_dir == "/var/lib/raycore" and settings.data_bytes == 1000
    assert load_settings({}).data_dir is None
    for name, value in (("RAYCORE_DATA_DIR", " "), ("RAYCORE_DATA_BYTES", "lots")):
        with pytest.raises(ValueError, match=name):
            load_settings({name: value})
