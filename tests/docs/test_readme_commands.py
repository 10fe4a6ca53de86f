"""The README's contract with its users and with CI: its first code block holds exactly two
command lines (``.ci/run`` reads and runs them verbatim), line 1 sets up and runs the whole
main job failing on any arm or claim that is not a pass, line 2 runs the tests; both are
typed from the clone's own folder (the models found relative to it)."""
from support.paths import REPO_ROOT

def first_code_block() -> list[str]:
    """The lines of the README's first fenced block (the rule `.ci/run` applies with awk)."""
    lines, block = [], 0
    for line in (REPO_ROOT / "README.md").read_text().splitlines():
        if line.startswith("```"):
            block += 1
            continue
        if block == 1:
            lines.append(line)
    return lines


def test_first_code_block_is_setup_plus_main_job_then_tests():
    setup_and_main, tests = first_code_block()
    assert setup_and_main.startswith("python3 -m venv .venv && .venv/bin/pip install -e '.[test]' && ")
    assert " -m scenarios run all " in setup_and_main and "--require-pass" in setup_and_main
    assert "--out runs" in setup_and_main  # relative, as users type it
    assert tests.endswith(".venv/bin/python -m pytest -q -n 2")  # two workers: the 2-core machine
    for line in (setup_and_main, tests):
        assert "MENAGERIE_ROOT=../shared/cassie/menagerie " in line
        assert "/work/" not in line and "/tmp/" not in line  # nothing of one machine
