import pytest

from markerplan.errors import ConfigError, InputFileError
from planner.config import PlanConfig, config_from_dict, load_config


def test_defaults_match_the_requirement():
    c = PlanConfig()
    assert c.requirement_m == 0.10
    assert (c.n_sectors, c.min_sectors, c.min_markers) == (6, 3, 3)
    assert c.grid_spacing_m == 1.0


def test_toml_loads_and_unknown_keys_are_named(tmp_path):
    p = tmp_path / "plan.toml"
    p.write_text('requirement_m = 0.05\nn_sectors = 8\nforbidden = ["C00001"]\n')
    c = load_config(p)
    assert c.requirement_m == 0.05 and c.n_sectors == 8 and c.forbidden == ("C00001",)
    p.write_text("requirment_m = 0.05\n")
    with pytest.raises(ConfigError, match="requirment_m"):
        load_config(p)


@pytest.mark.parametrize("bad", [{"requirement_m": 0}, {"min_sectors": 7},
                                 {"max_slope_deg": 95}, {"budget": 0},
                                 {"min_visible_fraction": 1.5}, {"redundant": "yes"},
                                 {"existing": ["A"], "forbidden": ["A"]},
                                 {"pass_rate_samples": -1}, {"pass_rate_samples": 2.5}])
def test_invalid_values_are_refused(bad):
    with pytest.raises(ConfigError):
        config_from_dict(bad)


def test_bad_toml_file(tmp_path):
    with pytest.raises(InputFileError, match="not found"):
        load_config(tmp_path / "missing.toml")
    p = tmp_path / "bad.toml"
    p.write_text("requirement_m = = 1")
    with pytest.raises(InputFileError, match="TOML"):
        load_config(p)


def test_replace_validates_and_rejects_unknown():
    assert PlanConfig().replace(redundant=True).redundant
    with pytest.raises(ConfigError, match="nope"):
        PlanConfig().replace(nope=1)
