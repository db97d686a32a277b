"""Sweep specs, the sweep table, ranking, failures and reruns (in-process, no Dask cluster)."""
import csv
import json

import numpy as np
import pytest

from labapp.figures.contact_sheet import printable, rank, top_view, views
from labapp.records.outpaths import OutPathError
from labapp.scaleout.sweep import SweepError, folder_state, run_sweep
from labapp.scaleout.sweepspec import SpecError, combination_name, load_spec, parse_spec, spec_text

SMALL = 'target = "pill"\nspace = "extruded"\nresolution = 16\nmax_iter = 6\n'


def test_grid_and_points_make_named_combinations(tmp_path):
    (tmp_path / "t.csv").write_text("tau_mm,released_mm3\n0,0\n1,1\n")
    spec_path = tmp_path / "s.toml"
    spec_path.write_text('target = "t.csv"\nresolution = 24\nw_binary = 5\n[grid]\nw_binary = [10, 20.5]\n'
                         'rate_span = [[0.0, 1.0]]\n[[points]]\nbeta = 4\n')
    spec = load_spec(spec_path)
    assert spec.target == str(tmp_path / "t.csv")  # relative to the spec's folder, made absolute
    names = [c.name for c in spec.combinations]
    assert names == ["rate_span=0x1,w_binary=10", "rate_span=0x1,w_binary=20.5", "beta=4"]
    configs = [c.config for c in spec.combinations]
    assert [c.w_binary for c in configs] == [10, 20.5, 5]  # a point keeps the top-level value
    assert configs[0].rate_span == (0.0, 1.0) and configs[2].beta == 4 and configs[0].resolution == 24
    assert spec.swept_keys == ("w_binary", "beta", "rate_span")
    assert combination_name({"w_binary": 1.0, "preset": "paper:pill"}) == "preset=paper-pill,w_binary=1"
    assert [c.name for c in parse_spec(SMALL).combinations] == ["default"]


@pytest.mark.parametrize("text, match", [
    ("resolution = 16\n", "'target' is required"),
    (SMALL + "w_bin = 3\n", "unknown key 'w_bin'"),
    (SMALL + "[grid]\nw_binary = 3\n", "grid.w_binary must be a non-empty list"),
    (SMALL + "[grid]\nradius = [3]\n", "unknown key 'radius' in \\[grid\\]"),
    (SMALL + "[grid]\nbeta = ['a']\n", "grid.beta must be a number, got 'a'"),
    (SMALL + "[grid]\nmax_iter = [2.5]\n", "grid.max_iter must be an integer"),
    (SMALL + "[[points]]\nbeta = 100\n", "combination beta=100: beta must be in \\(0, 64\\]"),
    (SMALL + "[[points]]\n", "points\\[0\\] is empty"),
    (SMALL + "[[points]]\nbeta = 3\n[[points]]\nbeta = 3.0\n", "appears twice"),
    (SMALL + "resolution = = 3\n", "not valid TOML"),
])
def test_bad_specs_name_the_key(text, match):
    with pytest.raises(SpecError, match=match):
        parse_spec(text, source="s.toml")


def test_presets_fill_what_the_spec_leaves_open():
    spec = parse_spec(SMALL + 'beta = 5\n[grid]\npreset = ["paper:pill", "paper:design-4"]\n')
    pill, design4 = (c.config for c in spec.combinations)
    assert [c.name for c in spec.combinations] == ["preset=paper-pill", "preset=paper-design-4"]
    assert (pill.w_binary, pill.radius_vox, pill.beta) == (20.0, 4.0, 5)  # Table 1, extruded; beta given
    assert design4.w_binary == 10.0 and design4.height_fraction == pytest.approx(200 / 256)  # Table 2
    assert spec.swept_keys == ("preset",)
    with pytest.raises(SpecError, match="combination preset=paper-nope: unknown preset 'paper:nope'"):
        parse_spec(SMALL + '[[points]]\npreset = "paper:nope"\n')


def test_measured_targets_need_a_readable_simcal(tmp_path):
    measured = tmp_path / "curve.csv"
    measured.write_text("t_s,released_g\n0,0\n60,0.1\n")
    with pytest.raises(SpecError, match="is a measured curve: add simcal"):
        parse_spec(f'target = "{measured}"\n')
    (tmp_path / "simcal.json").write_text("{}")
    with pytest.raises(SpecError, match="simcal: .*simcal.json"):
        parse_spec('target = "curve.csv"\nsimcal = "simcal.json"\n', base_dir=tmp_path)


def test_spec_text_round_trips(tmp_path):
    (tmp_path / 'a "b".csv').write_text("tau_mm,released_mm3\n0,0\n1,1\n")
    text = spec_text('a "b".csv', {"space": "nfc", "resolution": 16, "allow_infeasible": True},
                     {"w_binary": [10, 20.5]}, [{"preset": "paper:pill"}])
    spec = parse_spec(text, base_dir=tmp_path)
    assert spec.target == str(tmp_path / 'a "b".csv') and spec.combinations[0].config.allow_infeasible
    assert [c.name for c in spec.combinations] == ["w_binary=10", "w_binary=20.5", "preset=paper-pill"]


def test_a_measured_target_goes_through_the_simulation_calibration(tmp_path):
    from labapp.records.simcal import FORMAT, FORWARD_MODEL

    (tmp_path / "simcal.json").write_text(json.dumps({
        "format": FORMAT, "forward_model": FORWARD_MODEL,
        "physics": {"anisotropy": 1.0, "offset_mm": 0.0}, "model": "constant", "seconds_per_mm": 1500.0,
        "g_per_mm3": 1.3e-3, "resolution": 16, "voxel_size_mm": 1.0, "water_g": 500.0}))
    t_s = np.linspace(0.0, 6000.0, 60)                  # a 5 mm sphere dissolving at 1500 s/mm, in grams
    depth = np.minimum(t_s / 1500.0, 5.0)
    grams = 4 / 3 * np.pi * (5.0**3 - (5.0 - depth) ** 3) * 1.3e-3
    (tmp_path / "measured.csv").write_text("t_s,released_g\n" + "".join(f"{t},{g}\n" for t, g in zip(t_s, grams)))
    spec = parse_spec('target = "measured.csv"\nsimcal = "simcal.json"\nresolution = 16\nmax_iter = 6\n'
                      'allow_infeasible = true\n[grid]\nw_binary = [10, 20]\n', base_dir=tmp_path)
    rows = run_sweep(spec, tmp_path / "sweep", contact_sheet=False).rows
    assert [r["status"] for r in rows] == ["max_iter", "max_iter"]
    assert all(0 < r["rel_rmse_physical"] < 1 for r in rows)  # the prediction in grams against the measurement
    assert (tmp_path / "sweep" / "runs" / "w_binary=10" / "curves_physical.csv").is_file()
    again = run_sweep(spec, tmp_path / "sweep", contact_sheet=False)  # the stored target is the converted copy
    assert [r["status"] for r in again.rows] == ["max_iter", "max_iter"]
    assert (tmp_path / "sweep" / "sweep.log").read_text().count(" start ") == 2


def test_a_missing_spec_file_is_named(tmp_path):
    with pytest.raises(SpecError, match="cannot read the sweep spec .*nope.toml"):
        load_spec(tmp_path / "nope.toml")


def test_serial_sweep_records_failures_and_reruns_skip_done(tmp_path):
    # radius 32 voxels does not fit a 16-voxel grid: the design fails at run time, the sweep goes on
    spec = parse_spec(SMALL + "[grid]\nradius_vox = [2.0, 32.0]\n")
    out = tmp_path / "sweep"
    result = run_sweep(spec, out, contact_sheet=False)
    by_name = {r["name"]: r for r in result.rows}
    assert by_name["radius_vox=2"]["status"] == "max_iter"
    assert by_name["radius_vox=32"]["status"] == "failed" and "exceeds the grid" in by_name["radius_vox=32"]["error"]
    assert "exceeds the grid" in (out / "failed" / "radius_vox=32.txt").read_text()
    with open(out / "sweep.csv", newline="") as fh:
        table = list(csv.DictReader(fh))
    assert [r["name"] for r in table] == ["radius_vox=2", "radius_vox=32"]
    assert table[0]["iterations"] == "6" and float(table[0]["rmse_mm3"]) > 0 and table[1]["status"] == "failed"
    assert float(table[0]["enclosed_void_mm3"]) >= 0 and table[1]["enclosed_void_mm3"] == ""
    summary = json.loads((out / "runs" / "radius_vox=2" / "summary.json").read_text())
    # six evaluations leave the design grey: no solid, so no print to judge (a blank), the design grid's figure
    assert summary["rel_rmse_print"] is None and table[0]["rel_rmse_print"] == ""
    assert float(table[0]["rel_rmse_design_grid_binary"]) == pytest.approx(summary["rel_rmse_design_grid_binary"])
    assert table[1]["rel_rmse_print"] == table[1]["rate_dev_print"] == ""
    done = out / "runs" / "radius_vox=2"
    assert folder_state(done) == "done"
    stamp = (done / "summary.json").stat().st_mtime_ns
    # a rerun with a longer grid: the done design is skipped, the new one runs, the failure is retried
    again_text = SMALL + "[grid]\nradius_vox = [2.0, 3.0, 32.0]\n"
    again = run_sweep(parse_spec(again_text), out)
    assert (done / "summary.json").stat().st_mtime_ns == stamp
    assert [r["status"] for r in again.rows] == ["max_iter", "max_iter", "failed"]
    assert (out / "contact_sheet.png").stat().st_size > 10_000
    assert (out / "spec.toml").read_text() == spec.text  # the first spec is kept, the changed one beside it
    assert [p.read_text() for p in out.glob("spec-*.toml")] == [again_text]
    log = (out / "sweep.log").read_text()
    assert log.count("finish radius_vox=2 ") == 1 and log.count("failed radius_vox=32 ") == 2


def test_stopped_designs_resume_from_their_checkpoint(tmp_path):
    from design.files.rundir import run_design
    from labapp.scaleout.sweep import prepare_sweep_dir

    spec = parse_spec(SMALL.replace("max_iter = 6", "max_iter = 12\ncheckpoint_every = 2"))
    out = prepare_sweep_dir(spec, tmp_path / "sweep")
    folder = out / "runs" / "default"
    polls = []
    stopped = run_design(spec.combinations[0].config, folder, should_stop=lambda: len(polls) > 5 or polls.append(1))
    assert stopped.status == "stopped" and folder_state(folder) == "resume"
    result = run_sweep(spec, out, contact_sheet=False)
    history = np.loadtxt(folder / "history.csv", delimiter=",", skiprows=1)
    assert result.rows[0]["status"] == "max_iter"
    assert history[:, 0].tolist() == list(range(1, 13))  # continued from evaluation 6, not restarted
    assert "(resume)" in (out / "sweep.log").read_text()


def test_a_start_killed_before_its_config_is_set_aside(tmp_path):
    spec = parse_spec(SMALL)
    folder = tmp_path / "sweep" / "runs" / "default"
    folder.mkdir(parents=True)
    (tmp_path / "sweep" / "spec.toml").write_text(spec.text)
    (folder / "target_source.json").write_text("{}")
    assert run_sweep(spec, tmp_path / "sweep", contact_sheet=False).rows[0]["status"] == "max_iter"
    [aside] = (tmp_path / "sweep" / "failed").glob("default.aborted-*")
    assert (aside / "target_source.json").read_text() == "{}"


def test_out_checks_before_any_work(tmp_path):
    spec = parse_spec(SMALL)
    (tmp_path / "file").write_text("x")
    with pytest.raises(OutPathError, match="is a file"):
        run_sweep(spec, tmp_path / "file")
    (tmp_path / "other").mkdir()
    (tmp_path / "other" / "notes.txt").write_text("x")
    with pytest.raises(OutPathError, match="a folder with other files, not a sweep folder"):
        run_sweep(spec, tmp_path / "other")
    run_sweep(spec, tmp_path / "s", contact_sheet=False)
    with pytest.raises(SweepError, match="holds a design with other settings"):
        run_sweep(parse_spec(SMALL.replace("max_iter = 6", "max_iter = 7")), tmp_path / "s")


def test_ranking_puts_printable_good_fits_first():
    # ranked by the print's fit; a run recorded before it (d) by its design grid's binary fit
    rows = [{"name": "a", "status": "failed", "rel_rmse_print": ""},
            {"name": "b", "status": "max_iter", "rel_rmse_print": 0.01, "pieces": 2},
            {"name": "c", "status": "max_iter", "rel_rmse_print": 0.05, "rel_rmse_design_grid_binary": 0.001,
             "pieces": 1, "min_channel_mm": 2.0, "warn_channel_mm": 1.0},
            {"name": "d", "status": "converged", "rel_rmse_design_grid_binary": 0.03, "pieces": 1, "min_channel_mm": "",
             "warn_channel_mm": 1.0},
            {"name": "e", "status": "stopped", "rel_rmse_print": 0.001, "pieces": 1},
            {"name": "f", "status": "max_iter", "rel_rmse_print": 0.02, "pieces": 1, "min_channel_mm": 0.5,
             "warn_channel_mm": 1.0}]
    assert [r["name"] for r in rank(rows)] == ["d", "c", "b", "f", "e", "a"]
    assert not printable(rows[5]) and printable(rows[3])


def test_top_view_is_the_height_of_the_top_voxel():
    solid = np.zeros((2, 3, 4), dtype=bool)
    solid[0, 0, :2] = True
    solid[1, 2, 3] = True
    solid[1, 1, 1:3] = True
    assert top_view(solid, 2).tolist() == [[2, 0, 0], [0, 3, 4]]
    both = views(solid, 2)  # top view, two empty columns, side view along y (depth 1..3)
    assert both.shape == (2, 3 + 2 + 4) and both[:, 3:5].tolist() == [[0, 0], [0, 0]]
    assert both[:, 5:].tolist() == [[1, 1, 0, 0], [0, 2, 2, 3]]


def test_local_workers_get_one_blas_thread_and_glibcs_own_malloc_thresholds():
    import os

    from labapp.scaleout.cluster import dask_client
    with dask_client(workers=1) as client:
        env = next(iter(client.run(lambda: dict(os.environ)).values()))
    assert env["OMP_NUM_THREADS"] == env["OPENBLAS_NUM_THREADS"] == "1"
    assert "MALLOC_TRIM_THRESHOLD_" not in env     # a fixed threshold made every design ~1.8x slower


def test_a_second_local_cluster_takes_another_dashboard_port_without_a_warning(recwarn):
    from labapp.scaleout.cluster import dashboard_link, dask_client
    with dask_client(workers=1) as first, dask_client(workers=1) as second:
        links = dashboard_link(first), dashboard_link(second)
    assert links[0] and links[1] and links[0] != links[1]
    assert not [w for w in recwarn if "already in use" in str(w.message)]


def test_the_cluster_starts_the_costliest_designs_first(tmp_path):
    from distributed import Client, LocalCluster

    from labapp.scaleout.sweep import expected_work

    spec = parse_spec(SMALL + "[grid]\nresolution = [16, 24]\nmax_iter = [3, 6]\n")
    assert [expected_work(c) for c in spec.combinations] == [16**3 * 3, 16**3 * 6, 24**3 * 3, 24**3 * 6]
    with LocalCluster(n_workers=1, threads_per_worker=1, processes=False, dashboard_address=":0") as cluster, \
            Client(cluster) as client:
        run_sweep(spec, tmp_path / "sweep", client, contact_sheet=False)
    starts = [line.split(" start ")[1].split(" on ")[0]
              for line in (tmp_path / "sweep" / "sweep.log").read_text().splitlines() if " start " in line]
    assert starts == [c.name for c in sorted(spec.combinations, key=expected_work, reverse=True)]
