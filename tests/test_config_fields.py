"""Configuration fields explain themselves: every field of every configuration model has a
one-line description with its unit, `config show` writes it as a comment above each key and
`--schema` carries it, a misspelt key is answered with the closest name, and
docs/configuration.md is generated from the models."""

from __future__ import annotations

import ast
import importlib
import json

import pytest
from conftest import REPO, one_error_line, run_cli

from flexreg.config import Config, attribute_descriptions, did_you_mean, load_config, to_toml
from flexreg.errors import ConfigError

#: unit words by field-name suffix (rule 5: units in names where unclear)
UNITS = {
    "per_m": "per metre",
    "mm": "millimetres",
    "m": "metres",
    "deg": "degrees",
    "rad": "radians",
    "px": "pixel",
    "pixels": "pixels",
    "s": "seconds",
    "hz": "hertz",
    "mps": "metres per second",
}


def _config_classes() -> list[type[Config]]:
    """Every class of ``flexreg`` that derives from Config, found in the source (so that a new
    model cannot be missed) and imported."""
    found = []
    for path in sorted((REPO / "flexreg").rglob("*.py")):
        tree = ast.parse(path.read_text(encoding="utf-8"))
        for node in ast.walk(tree):
            if isinstance(node, ast.ClassDef) and any(
                getattr(b, "id", getattr(b, "attr", None)) == "Config" for b in node.bases
            ):
                parts = path.relative_to(REPO).with_suffix("").parts
                module = importlib.import_module(".".join(parts))
                found.append(getattr(module, node.name))
    return found


CLASSES = _config_classes()


def _unit(field: str) -> str | None:
    for suffix, unit in UNITS.items():
        if field.endswith("_" + suffix):
            return unit
    return None


def test_the_models_are_found():
    names = {cls.__name__ for cls in CLASSES}
    assert {"RegistrationConfig", "SurveyConfig", "CalibrationConfig", "BenchConfig"} <= names
    assert {"OdometryConfig", "EvaluationConfig", "CompareConfig", "ConvertConfig"} <= names
    assert {"SynthConfig", "TLSConfig", "RGBDConfig"} <= names


@pytest.mark.parametrize("cls", CLASSES, ids=lambda c: c.__name__)
def test_every_field_has_a_one_line_description_with_its_unit(cls):
    missing = [name for name, f in cls.model_fields.items() if not f.description]
    assert not missing, (
        f"{cls.__name__}: no description for {', '.join(missing)}: describe each in the "
        "Attributes section of the class docstring (first sentence: its meaning; type slot: "
        "its unit, `name : float, metres`)"
    )
    for name, field in cls.model_fields.items():
        text = field.description or ""
        assert "\n" not in text and not text.startswith(("...", "See ", "The same")), name
        unit = _unit(name)
        if unit is not None:
            assert unit in text, f"{cls.__name__}.{name}: no unit ({unit}) in {text!r}"


def test_descriptions_come_from_the_docstring():
    class Demo:
        """A demo.

        Attributes
        ----------
        n : int, pixels
            Window size (odd). Larger is smoother.
        lo_m, hi_deg : float, metres and degrees
            Limits (:data:`~flexreg.config.MAX_VOXEL_M`, ``x``).
        bare : bool

        Notes
        -----
        not : an attribute
            Of the next section.
        """

    assert attribute_descriptions(Demo) == {
        "n": "Window size (odd) [pixels]",
        "lo_m": "Limits (`MAX_VOXEL_M`, `x`) [metres]",
        "hi_deg": "Limits (`MAX_VOXEL_M`, `x`) [degrees]",
    }


@pytest.mark.parametrize("name", ["register", "survey", "bench", "pick"])
def test_config_show_writes_each_description_above_its_key(name):
    from flexreg.cli.config_cmd import CONFIGS

    rc, out, err = run_cli(["config", "show", name])
    assert rc == 0, err
    config = CONFIGS[name]()
    lines = out.splitlines()
    dumped = config.model_dump(mode="json")
    for key, field in type(config).model_fields.items():
        value = dumped[key]
        line = f"[{key}]" if isinstance(value, dict) else f"{key} = "
        if value is None:
            line = f"# {key} = none"
        at = next(i for i, text in enumerate(lines) if text.startswith(line))
        comment = []
        for text in reversed(lines[:at]):
            if not text.startswith("# ") or " = " in text:
                break
            comment.insert(0, text[2:])
        assert " ".join(comment) == field.description, key
        assert all(len(text) <= 100 for text in lines if text.startswith("#"))


def test_nested_tables_are_described_too():
    from flexreg.registration.config import RegistrationConfig

    rc, out, _ = run_cli(["config", "show", "survey"])
    assert rc == 0
    table = out[out.index("[registration]") :]
    assert f"# {RegistrationConfig.model_fields['seed'].description}\nseed = 0" in table
    assert "\n# The pairwise registration of every link" in out


def test_comments_can_be_left_out():
    from flexreg.registration.config import RegistrationConfig

    text = to_toml(RegistrationConfig(), comments=False)
    assert not [line for line in text.splitlines() if line.startswith("#") and " = " not in line]


@pytest.mark.parametrize("name", ["register", "survey", "calibrate", "compare"])
def test_schema_carries_the_descriptions(name):
    rc, out, _ = run_cli(["config", "show", name, "--schema"])
    assert rc == 0
    schema = json.loads(out)
    for model in [schema, *schema.get("$defs", {}).values()]:
        for key, prop in model["properties"].items():
            assert prop.get("description"), f"{model['title']}.{key}"
    if name == "register":
        assert schema["properties"]["threshold_m"]["description"].endswith("[metres]")


def test_config_show_pick_is_the_calibration_that_pick_runs(tmp_path):
    from flexreg.calibration.config import CalibrationConfig

    rc, out, err = run_cli(["config", "show", "pick"])
    assert rc == 0, err
    assert out.startswith("# flexreg pick: default configuration (CalibrationConfig).")
    (tmp_path / "p.toml").write_text(out)
    assert load_config(CalibrationConfig, tmp_path / "p.toml") == CalibrationConfig()
    rc, out, _ = run_cli(["pick", "--help"])
    assert rc == 0 and "config show" in out


# ---------------------------------------------------------------------------- misspelt keys


def test_did_you_mean():
    assert did_you_mean("Treshold_M", ["threshold_m", "seed"]) == "; did you mean threshold_m?"
    assert did_you_mean("zzz", ["n", "seed"]) == "; known: n, seed"
    many = [f"field_{i}" for i in range(20)]
    assert "none of the 20 known names is close" in did_you_mean("qqq", many)


@pytest.mark.parametrize(
    ("toml", "sets", "message"),
    [
        ("", ["treshold_m=0.05"], "error: --set treshold_m: unknown setting; did you mean "
         "threshold_m?"),
        ("", ["voxel=0.1"], "error: --set voxel: unknown setting; did you mean voxel_m?"),
        ("ration = 0.8\n", [], "error: {toml}: ration: unknown setting; did you mean ratio?"),
        ("no_such_field = 1\n", [], "error: {toml}: no_such_field: unknown setting; none of "),
    ],
)  # fmt: skip
def test_a_misspelt_key_names_the_closest_one(tmp_path, toml, sets, message):
    path = tmp_path / "r.toml"
    path.write_text(toml)
    argv = ["register", tmp_path / "a.ptx", tmp_path / "b.ptx", "--out", tmp_path / "T.json"]
    extra = [x for item in sets for x in ("--set", item)]
    rc, _, err = run_cli([*argv, "--config", path, *extra])
    assert rc == 1
    line = one_error_line(err)
    assert line.startswith(message.format(toml=path)), line
    assert "image, n, median" not in line


def test_a_misspelt_key_of_a_nested_table(tmp_path):
    from flexreg.survey.config import SurveyConfig

    with pytest.raises(ConfigError, match=r"^registration\.ration: unknown setting; did you "):
        SurveyConfig(registration={"ration": 0.8})
    (tmp_path / "s.toml").write_text("[registration]\nration = 0.8\n")
    with pytest.raises(ConfigError, match=r"ration: unknown setting; did you mean ratio\?$"):
        load_config(SurveyConfig, tmp_path / "s.toml")


# ------------------------------------------------------------------------------ the reference


def test_docs_configuration_md_is_generated_from_the_models():
    from flexreg.cli.config_cmd import UPDATE_DOCS, update_docs

    path = REPO / "docs" / "configuration.md"
    text = path.read_text(encoding="utf-8")
    assert "<!-- generated: fields -->" in text and "<!-- generated: commands -->" in text
    assert update_docs(text) == text, f"{path.name} is out of date; run: {UPDATE_DOCS}"


def test_config_docs_lists_every_field(tmp_path):
    from flexreg.cli.config_cmd import CONFIGS

    rc, out, _ = run_cli(["config", "docs"])
    assert rc == 0
    for name in CONFIGS:
        config = CONFIGS[name]()
        assert f"`flexreg {name}`" in out
        for key in type(config).model_fields:
            assert f"| `{key}` |" in out or f"| `[{key}]` |" in out, (name, key)
    stale = tmp_path / "c.md"
    stale.write_text("# x\n<!-- generated: commands -->\nold\n<!-- end generated: commands -->\n")
    assert run_cli(["config", "docs", "--update", stale])[0] == 0
    text = stale.read_text()
    assert "old" not in text and "`RegistrationConfig` | 24 (+ 6 in `[prior]`) (+ 10 in" in text


def test_a_misspelt_survey_set_names_the_closest_field(tmp_path):
    """``survey --set`` takes fields of the survey and of its registration alike: a misspelt
    one names the closest of both, in one line, before anything is read."""
    for given, meant in (("neighbors=2", "neighbours"), ("tolerance_m=5", "tolerance_mm"),
                         ("treshold_m=0.05", "threshold_m")):  # fmt: skip
        rc, _, err = run_cli(["survey", tmp_path, "--out", tmp_path / "o", "--set", given])
        assert rc == 1
        assert one_error_line(err).endswith(f"; did you mean {meant}?")
    assert not (tmp_path / "o").exists()


def test_configurations_stay_within_their_field_budgets():
    """Every field a user may set counts, a table's fields included: the registration keeps
    at most 40 (the front end's knobs, the prior's and the judge's tables), the survey's own
    fields at most their number today (its registration counted apart), so that a new
    threshold replaces one instead of joining the pile."""
    from flexreg.registration.config import RegistrationConfig, leaf_fields
    from flexreg.survey.config import SurveyConfig

    assert len(leaf_fields(RegistrationConfig)) <= 40
    own = [f for f in leaf_fields(SurveyConfig) if not f.startswith("registration.")]
    assert len(own) <= 36
    for table in ("prior", "judge"):  # nested by stage, each field described with its unit
        cls = type(getattr(RegistrationConfig(), table))
        assert all(f.description for f in cls.model_fields.values()), table
