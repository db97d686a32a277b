"""The design settings are declared once (`design.inverse.settings`): `DesignConfig`'s defaults and checks come from
the declarations, defaults that depend on other settings are resolved apart from the checks, and the shared
constants are defined once."""
import dataclasses
import re
from pathlib import Path

import pytest

from design.errors import DesignError
from design.inverse.config import DesignConfig, check_config, resolved_defaults
from design.inverse.filters import MAX_RADIUS_VOX
from design.inverse.settings import OPTIONS, RADIUS, RESOLUTION, SETTINGS, option_flag

ROOT = Path(__file__).resolve().parents[3]


def test_every_field_but_the_target_is_declared_with_the_configs_default():
    fields = {f.name: f for f in dataclasses.fields(DesignConfig)}
    assert set(fields) - {"target"} == set(SETTINGS)
    for name, setting in SETTINGS.items():
        assert fields[name].default == setting.default, name
    assert len({s.flag for s in OPTIONS}) == len(OPTIONS) and all(s.flag for s in OPTIONS)
    assert option_flag("radius_vox") == "--radius" and option_flag("checkpoint_every") == "--checkpoint-every"


def _unresolved(**given) -> DesignConfig:
    """A configuration as given, before its defaults are resolved and checked."""
    config = object.__new__(DesignConfig)
    for field in dataclasses.fields(DesignConfig):
        object.__setattr__(config, field.name, given.get(field.name, field.default))
    return config


def test_resolving_defaults_is_apart_from_checking_them():
    resolved = resolved_defaults(_unresolved(target="zero-order", space="extruded"))
    assert resolved == {"w_binary": 30.0, "beta": 3.0, "beta_final": 64.0, "w_connect": 10.0, "w_fab": 0.0,
                        "w_rate": 1.0, "robust_eta": 0.1, "starts": 3, "physical_correction": "defect",
                        "correction_evals": 50}
    config = DesignConfig(target="zero-order", space="extruded")
    assert resolved_defaults(config) == {}          # nothing left to resolve
    check_config(config)
    with pytest.raises(DesignError, match=r"resolution must be an even number >= 8 voxels, got 9"):
        check_config(dataclasses.replace(config, resolution=9))
    assert not RESOLUTION.allows(9) and RESOLUTION.allows(8) and RESOLUTION.range_text() == ">= 8 voxels (even)"


def test_the_smoothing_radius_is_capped_once_in_voxels_as_in_mm():
    assert RADIUS.high == MAX_RADIUS_VOX == 64
    assert DesignConfig(target="sphere", radius_vox=MAX_RADIUS_VOX).radius_vox == MAX_RADIUS_VOX
    with pytest.raises(DesignError, match=r"smoothing radius must be in \[1, 64\] voxels"):
        DesignConfig(target="sphere", radius_vox=MAX_RADIUS_VOX + 0.5)


@pytest.mark.parametrize("pattern", [r"=\s*1001\b", r"^\s*DEFAULT_RESOLUTION\s*=|resolution: int = 64\b"])
def test_the_tau_samples_and_the_resolution_default_are_defined_once(pattern):
    regex = re.compile(pattern, re.M)
    hits = [str(p.relative_to(ROOT)) for pkg in ("design", "labapp") for p in (ROOT / pkg).rglob("*.py")
            if regex.search(p.read_text())]
    assert hits == (["design/inverse/targets.py"] if "1001" in pattern else ["design/geometry/voxelize.py"])
