"""Bad input on the command lines ends in one clear line per problem, on the right input, and exit 2;
never a traceback, never a run (issue 44).

- the same scenario named twice is refused up front, naming it;
- ``--duration``/``--model`` values are reported once as command-line errors, not under each file;
- no option abbreviations (``--job 1`` is not ``--jobs 1``); an unknown option is reported with
  the subcommand's own usage and the closest option;
- a missing file, a file that is not what it should be, a folder, for ``scenarios`` and
  ``scenarios.ssp.ssp_check``.

The commands run in this process (``cli.main``); ``ssp_check`` as ``python -m``, as documented.
"""
from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

from scenarios.cli import main as cli_main
from support.paths import REPO_ROOT
from support.scenario_support import scenario_file


def cli(capsys, *argv) -> tuple[int, str, str]:
    try:
        rc = cli_main([str(a) for a in argv])
    except SystemExit as exc:  # argparse's own errors
        rc = exc.code
    cap = capsys.readouterr()
    return rc, cap.out, cap.err


def test_the_same_scenario_named_twice_is_refused_naming_it(tmp_path, capsys):
    f = scenario_file(tmp_path, "twice")
    out = tmp_path / "out"
    for targets, by in (([f, f], f"{str(f)!r} twice"), (["nominal", "nominal"], "'nominal' twice"),
                        (["all", "nominal"], "'all' and 'nominal'")):
        rc, stdout, err = cli(capsys, "run", *targets, "--out", out, "--regulator", "inprocess", "--duration", "0.5")
        name = "twice" if targets[0] == f else "nominal"
        assert rc == 2 and f"{name!r}: named twice on the command line (by {by})" in err, err
        assert stdout == "" and not out.exists()
    rc, _, err = cli(capsys, "validate", f, f)
    assert rc == 2 and "'twice': named twice" in err, err


def test_command_line_values_are_reported_once_as_command_line_errors(tmp_path, capsys):
    rc, stdout, err = cli(capsys, "run", "all", "--duration", "-5", "--model", "osuu", "--out", tmp_path / "out")
    assert rc == 2 and stdout == "" and not (tmp_path / "out").exists()
    assert err.splitlines() == ["--model = 'osuu': must be one of menagerie, osu or an existing MJCF (.xml) path",
                                "--duration = -5: must be > 0"], err
    # what a good value does to one scenario stays that scenario's problem, under its file
    f = scenario_file(tmp_path, "grid")
    rc, _, err = cli(capsys, "run", f, "--duration", "0.0033", "--out", tmp_path / "out")
    assert rc == 2 and f"{f}: 1 problem(s)" in err and "--duration = 0.0033: must be a whole number" in err, err


@pytest.mark.parametrize("argv, command, hint", [
    (["run", "nominal", "--job", "1"], "run", "--job: unknown option; did you mean '--jobs'?"),
    (["run", "nominal", "--jbos=2"], "run", "--jbos: unknown option; did you mean '--jobs'?"),
    (["run", "nominal", "--dur", "1"], "run", "--dur: unknown option"),
    (["campaign", "smoke", "--worker", "2"], "campaign", "--worker: unknown option; did you mean '--workers'?"),
    (["export-ssp", "nominal", "--armm", "pd_only"], "export-ssp", "--armm: unknown option; did you mean '--arm'?"),
])
def test_no_abbreviations_and_unknown_options_get_the_subcommands_usage(tmp_path, capsys, argv, command, hint):
    rc, stdout, err = cli(capsys, *argv, "--out", tmp_path / "out")
    assert rc == 2 and stdout == "", err
    assert err.startswith(f"usage: python -m scenarios {command} ") and hint in err, err
    assert not (tmp_path / "out").exists()


def test_missing_wrong_and_folder_files_are_one_line_each_exit_2(tmp_path, capsys):
    (tmp_path / "folder").mkdir()
    (tmp_path / "notzip.fmu").write_text("not an FMU")
    (tmp_path / "bin.toml").write_bytes(b"\x00\x01 not TOML")
    missing, folder, notzip = tmp_path / "missing.toml", tmp_path / "folder", tmp_path / "notzip.fmu"
    cases = [
        (["run", missing], f"file not found: {missing}"),
        (["run", folder], f"{folder}: is a directory, not a scenario file"),
        (["validate", tmp_path / "bin.toml"], f"{tmp_path / 'bin.toml'}"),
        (["run", "nominal", "--fmu", notzip], f"--fmu {notzip}: not a readable FMU"),
        (["run", "nominal", "--fmu", folder], f"--fmu {folder}: is a folder, not an FMU file"),
        (["run", "nominal", "--plant", "fmu", "--plant-fmu", folder], f"--plant-fmu {folder}: is a folder"),
        (["export-ssp", "nominal", "--fmu", notzip, "--plant-fmu", folder, "--command-fmu", missing],
         f"--fmu {notzip}: not a readable FMU"),
        (["export-ssp", missing], f"file not found: {missing}"),
        (["campaign", missing], f"file not found: {missing}"),
        (["campaign", folder], "is a directory, not a campaign file"),
        (["campaign", "smoke", "--fmu", folder], f"--fmu {folder}: is a folder, not an FMU file"),
        (["report", missing], f"no such results folder: {missing}"),
    ]
    for argv, message in cases:
        out = ["--out", tmp_path / "out"] if argv[0] in ("run", "campaign", "export-ssp") else []
        if argv[0] == "export-ssp":
            out = ["--out", tmp_path / "out.ssp"]
        rc, stdout, err = cli(capsys, *argv, *out)
        assert rc == 2 and message in err and "Traceback" not in err + stdout, (argv, err)
        assert not (tmp_path / "out").exists() and not (tmp_path / "out.ssp").exists(), argv
    rc, _, err = cli(capsys, "export-ssp", "nominal", "--fmu", notzip, "--plant-fmu", folder, "--command-fmu", missing)
    assert err.splitlines() == [f"--fmu {notzip}: not a readable FMU (BadZipFile: File is not a zip file)",
                                f"--plant-fmu {folder}: is a folder, not an FMU file",
                                f"--command-fmu {missing}: no such file"], err


@pytest.mark.parametrize("make, message", [
    (lambda d: d / "missing.ssp", "missing.ssp: cannot read: No such file or directory"),
    (lambda d: (d / "notzip.ssp").write_text("not a zip") and d / "notzip.ssp",
     "notzip.ssp: not an SSP archive (a zip file): File is not a zip file"),
    (lambda d: (d / "folder.ssp").mkdir() or d / "folder.ssp", "folder.ssp: is a folder, not an SSP archive"),
])
def test_ssp_check_on_a_missing_file_a_non_zip_and_a_folder(tmp_path, make, message):
    path = make(tmp_path)
    r = subprocess.run([sys.executable, "-m", "scenarios.ssp.ssp_check", path.name], cwd=tmp_path,
                       capture_output=True, text=True, timeout=120)
    assert (r.returncode, r.stdout, r.stderr) == (2, "", message + "\n")


def test_ssp_check_usage_errors_are_its_own(tmp_path):
    r = subprocess.run([sys.executable, "-m", "scenarios.ssp.ssp_check", "a.ssp", "--bogus"], cwd=tmp_path,
                       capture_output=True, text=True, timeout=120)
    assert r.returncode == 2 and r.stderr.startswith("usage: python -m scenarios.ssp.ssp_check")
    assert "--bogus: unknown option" in r.stderr and "Traceback" not in r.stderr


def test_every_parser_refuses_abbreviations():
    """Every command-line parser of the project is the one parser class (scenarios/lang/cmdline.py) or
    says allow_abbrev=False itself."""
    offenders = []
    for path in [REPO_ROOT / "build.py", *(REPO_ROOT / "scenarios").rglob("*.py"), *(REPO_ROOT / "benchmarks").rglob("*.py")]:
        for n, line in enumerate(path.read_text().splitlines(), 1):
            if "ArgumentParser(" in line and "allow_abbrev=False" not in line and "class Parser" not in line:
                offenders.append(f"{path.relative_to(REPO_ROOT)}:{n}")
    assert offenders == []
    assert Path(REPO_ROOT / "scenarios" / "lang" / "cmdline.py").is_file()
