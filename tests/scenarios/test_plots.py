"""The scenario plots reuse one figure per layout and process
(:func:`scenarios.results.plots._figure`): what an earlier scenario drew must not show
in the next one, so a reused figure must give the same PNG bytes as a new one."""
import dataclasses

import numpy as np

from scenarios.cosim import master
from scenarios.lang import spec
from scenarios.results import plots


def scenario(name: str, duration_s: float):
    return spec.override(spec.resolve_targets([name])[0], duration_s=duration_s)


def pngs(folder) -> dict[str, bytes]:
    return {name: (folder / name).read_bytes() for name in plots.PLOTS}


def test_a_reused_figure_draws_the_same_png_as_a_new_one(tmp_path):
    first = scenario("compare_fixed_speed", 1.0)
    results = master.run_scenario(first, "inprocess")
    # The same layout with other data: more lines (falls), other limits, a perturbation line.
    second = scenario("push_fwd_30n", 1.0)
    shifted = []
    for r in results:
        rows = r.rows.copy()
        for name in rows.dtype.names:
            if name != "t" and rows[name].dtype.kind == "f":
                rows[name] = 3.0 * rows[name] + 1.0
        shifted.append(dataclasses.replace(r, rows=rows, fell=True, t_fall_s=0.5))
    for folder in ("new", "other", "reused"):
        (tmp_path / folder).mkdir()
    plots._FIGURES.clear()
    assert plots.write_plots(tmp_path / "new", first, results) == list(plots.PLOTS)
    layouts = set(plots._FIGURES)
    plots.write_plots(tmp_path / "other", second, shifted)
    assert set(plots._FIGURES) == layouts  # drawn in the same figures
    plots.write_plots(tmp_path / "reused", first, results)
    new, other, reused = (pngs(tmp_path / f) for f in ("new", "other", "reused"))
    assert reused == new
    assert all(other[name] != new[name] for name in plots.PLOTS)


def test_an_arm_without_rows_is_left_out_and_no_rows_draw_nothing(tmp_path):
    s = scenario("nominal", 0.2)
    results = master.run_scenario(s, "inprocess")
    empty = [dataclasses.replace(r, rows=r.rows[:0]) for r in results]
    assert plots.write_plots(tmp_path, s, empty) == []
    assert list(tmp_path.iterdir()) == []
    assert plots.write_plots(tmp_path, s, [results[0], empty[1]]) == list(plots.PLOTS)
    assert np.all([(tmp_path / n).stat().st_size > 0 for n in plots.PLOTS])


def test_the_psi_legend_names_every_arm_also_one_without_psi_outputs(tmp_path):
    s = scenario("compare_fixed_speed", 0.5)
    results = master.run_scenario(s, "inprocess")
    rows = results[1].rows  # an arm like rl_hzd: offsets, no psi_* outputs
    kept = [n for n in rows.dtype.names if not n.startswith("out_psi_")]
    policy = dataclasses.replace(results[1], arm="policy", rows=rows[kept])
    arms = [results[0].arm, policy.arm, results[1].arm]
    plots._FIGURES.clear()
    plots.write_plots(tmp_path, s, [results[0], policy, results[1]])
    ((_, axes),) = [v for k, v in plots._FIGURES.items() if k[0] == "psi"]
    assert [t.get_text() for t in axes[0][0].get_legend().get_texts()] == arms
