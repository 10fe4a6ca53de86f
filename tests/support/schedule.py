"""The order in which ``pytest -n N`` (pytest-xdist, ``--dist loadscope``) hands out the test
modules: each whole module goes to one worker, in the order of the collected items
(pyproject.toml's ``--no-loadscope-reorder`` leaves that order to :func:`order`).

Two parts: the modules that read no build first, so that the session's first tests run while its
build is made (``support.builds``), then those that read it.  Within each part the longest modules
go first (longest-processing-time-first): a long module handed out last runs alone while the
other workers have finished, which cost about 18 s of one idle core when modules with few but long
tests (SSP masters run again, BLAS kernels, a clean environment) were ordered last by their count
of tests.
"""
from __future__ import annotations

from support.builds import BUILD_FIXTURE

#: Wall seconds of each test module of at least 4 s under ``pytest -n 2`` (summed from the
#: modules' test durations, ``--durations=0``, on 2 cores); a module not listed counts as its
#: number of tests x 0.1 s.  Only the order depends on these: a wrong or stale number costs
#: time at the end of a run, never a test.
MODULE_SECONDS = {
    "ssp/test_ssp.py": 74,
    "native/test_native_plant.py": 58,
    "campaign/test_campaign_dask.py": 53,
    "docs/test_docs_examples.py": 49,
    "conformance/test_conformance.py": 43,
    "native/test_native_crosscheck.py": 43,
    "plant/test_blas_independence.py": 30,
    "fmu/test_plant_fmu.py": 25,
    "campaign/test_campaign_fork.py": 24,
    "scenarios/test_cli_results.py": 23,
    "scenarios/test_relative_paths.py": 20,
    "campaign/test_campaign_connect.py": 20,
    "fmu/test_fmu_clean_environment.py": 18,
    "plant/test_envelope.py": 18,
    "fmu/test_build_platforms.py": 17,
    "campaign/test_campaign_confirm.py": 16,
    "ssp/test_ssp_repeat.py": 16,
    "plant/test_native_controller.py": 16,
    "native/test_native_same_bits.py": 16,
    "plant/test_walking.py": 15,
    "fmu/test_fmu_compliance.py": 15,
    "plant/test_model.py": 14,
    "cosim/test_rl_hzd.py": 13,
    "fmu/test_fmu_coexistence.py": 12,
    "ssp/test_ssp_profiles.py": 11,
    "scenarios/test_render.py": 11,
    "cosim/test_plant_fmu_terrain.py": 11,
    "scenarios/test_fastpath.py": 10,
    "native/test_native_master.py": 9,
    "fmu/test_fmu_model_structure.py": 9,
    "cosim/test_cosim.py": 8,
    "fmu/test_fmu_call_sequences.py": 7,
    "native/test_native_plant_ssp.py": 7,
    "cosim/test_run_speed.py": 6,
    "cosim/test_yaw_rate_command.py": 5,
    "native/test_native_hosts.py": 5,
    "fmu/test_command_source.py": 5,
    "scenarios/test_report_tampered.py": 4,
}
#: Seconds counted per test of a module not in MODULE_SECONDS.
UNLISTED_TEST_S = 0.1


def module_seconds(path: str, n_tests: int) -> float:
    """The expected wall seconds of the module ``path`` (a node id's file part, ``tests/...``)."""
    return MODULE_SECONDS.get(path.removeprefix("tests/"), n_tests * UNLISTED_TEST_S)


def order(items) -> list:
    """``items`` grouped by module: those that read no build first, each part's longest modules
    first, each module's tests together and in their order."""
    modules: dict[str, list] = {}
    for item in items:
        modules.setdefault(item.nodeid.split("::")[0], []).append(item)
    reads = {name: any(BUILD_FIXTURE in getattr(i, "fixturenames", ()) for i in group)
             for name, group in modules.items()}
    ranked = sorted(modules, key=lambda name: (reads[name], -module_seconds(name, len(modules[name]))))
    return [i for name in ranked for i in modules[name]]
