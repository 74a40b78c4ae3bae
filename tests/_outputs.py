"""Shared check of a command's ``results.json`` provenance block and files list (issue 21)."""

import json

import jaxnav

#: keys every provenance block has
PROVENANCE_KEYS = {
    "jaxnav_version",
    "git_commit",
    "python_version",
    "jax_version",
    "date_utc",
    "finished_utc",
    "wall_time_s",
    "command",
    "argv",
    "cwd",
    "options",
    "config_file",
    "config",
    "subcommand",
}


def no_constants(name):
    raise AssertionError(f"{name} token in a JSON file")  # strict JSON: null + reason instead


def check_provenance(out, argv, *, json_name="results.json", config=False) -> dict:
    """The provenance block and files list of ``out/results.json`` (shared by the command tests)."""
    res = json.loads((out / "results.json").read_text(), parse_constant=no_constants)
    prov = res["provenance"]
    assert PROVENANCE_KEYS <= set(prov), PROVENANCE_KEYS - set(prov)
    assert prov["jaxnav_version"] == jaxnav.__version__ and prov["argv"] == [str(a) for a in argv]
    assert prov["command"].startswith("jaxnav ") and prov["date_utc"].endswith("+00:00")
    assert prov["subcommand"] == next(a for a in argv if not a.startswith("-"))
    assert isinstance(prov["options"], dict) and "out" in prov["options"]
    if config:
        assert prov["config_file"] and isinstance(prov["config"], dict) and prov["config"]
    files = res["files"]
    assert "results.json" in files and all((out / f).is_file() for f in files)
    if json_name != "results.json":
        own = json.loads((out / json_name).read_text(), parse_constant=no_constants)
        assert own["provenance"]["argv"] == prov["argv"] and json_name in files
    return res
