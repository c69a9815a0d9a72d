"""Equal-time studies: tidy records, identical results on every executor (serial, local process
pool, Dask LocalCluster), ratios and time-to-reach, CSV, the compare command."""
import argparse
import csv
import warnings

import numpy as np
import pytest

from experiments_fake import FakeGradient, FakePrimal, fake_solver, truth
from gdlearn.experiments import study as S
from gdlearn.experiments.executors import DaskExecutor, get_executor, LocalExecutor, SerialExecutor

# Columns that depend only on seeds and pass counts (not on the wall clock).
DETERMINISTIC = ("method", "estimator", "scene", "seed", "snapshot", "passes", "spp", "relmse",
                 "relmse_trimmed", "mse", "relmse_primal", "solver")


def _study(executor):
    methods = [FakePrimal, S.Method("fgpt", FakeGradient, fake_solver)]
    return S.equal_time(methods, [None], passes=12, seeds=[0, 1], count=4,
                        references={"none": truth()}, executor=executor)


def _table(study):
    return [tuple(r.get(k) for k in DETERMINISTIC) for r in study.records]


@pytest.fixture(scope="module")
def serial():
    return _study("serial")


def test_records_are_tidy(serial):
    recs = serial.records
    assert len(recs) == 2 * 2 * 4                     # methods x seeds x snapshots
    assert serial.methods() == ["fake-pt", "fgpt"] and serial.scenes() == ["none"]
    assert {r["solver"] for r in recs if r["method"] == "fgpt"} == {"fake_solver"}
    assert {r["solver"] for r in recs if r["method"] == "fake-pt"} == {None}
    assert sum(r["final"] for r in recs) == 4
    assert set(serial.images) == {(m, "none", s) for m in ("fake-pt", "fgpt") for s in (0, 1)}


def test_local_process_pool_matches_serial(serial):
    pooled = _study(LocalExecutor(max_workers=2))
    assert _table(pooled) == _table(serial)
    for k, img in serial.images.items():
        np.testing.assert_array_equal(pooled.images[k], img)


def test_dask_local_cluster_matches_serial(serial):
    with DaskExecutor(n_workers=2) as ex:             # LocalCluster on 127.0.0.1, closed on exit
        assert len(ex.client.scheduler_info()["workers"]) == 2
        dask = _study(ex)
    assert _table(dask) == _table(serial)
    for k, img in serial.images.items():
        np.testing.assert_array_equal(dask.images[k], img)


def test_ratios_and_time_to_reach_on_hand_made_records():
    recs = []
    for m, scale in (("a", 1.0), ("b", 0.25)):         # b has 4x lower error at every time
        for i, t in enumerate((1.0, 2.0, 4.0)):
            recs.append({"method": m, "scene": "s", "seed": 0, "final": i == 2, "seconds": t,
                         "relmse": scale / t})
    st = S.Study(recs)
    assert st.equal_time_ratios("a") == {("a", "s"): 1.0, ("b", "s"): 4.0}
    ttr = st.time_to_reach(0.5)
    assert ttr[("a", "s", 0)] == pytest.approx(2.0) and ttr[("b", "s", 0)] == pytest.approx(1.0)


def test_ratios_less_the_reference_floor():
    # against a reference with noise floor 1e-4, a method of own error 4e-4 reads 5e-4 and one of
    # own error 1e-4 reads 2e-4: 2.5x as measured, 4x between their own errors
    recs = [{"method": m, "scene": "s", "seed": sd, "final": True, "relmse": e + 1e-4, "relmse_floor": 1e-4}
            for m, own in (("a", (3e-4, 5e-4)), ("b", (0.5e-4, 1.5e-4))) for sd, e in enumerate(own)]
    recs.append({"method": "c", "scene": "s", "seed": 0, "final": True, "relmse": 0.9e-4, "relmse_floor": 1e-4})
    st = S.Study(recs)
    assert st.equal_time_ratios("a")[("b", "s")] == pytest.approx(2.5)
    less = st.equal_time_ratios("a", less_floor=True)
    assert less[("b", "s")] == pytest.approx(4.0) and less[("a", "s")] == pytest.approx(1.0)
    assert np.isnan(less[("c", "s")])            # below the floor: the reference cannot rank it
    with pytest.raises(ValueError, match="less_floor"):
        st.equal_time_ratios("a", metric="mse", less_floor=True)


def test_seed_ratios_pair_the_seeds():
    # b's error is a's over 2 on seed 0 and over 8 on seed 1: the paired ratios are 2 and 8 (the
    # ratio of the means, 5.0 / 1.125 = 4.44, is neither); c ran on seed 1 only
    recs = [{"method": m, "scene": "s", "seed": sd, "final": True, "relmse": e}
            for m, errs in (("a", (1.0, 4.0)), ("b", (0.5, 0.5))) for sd, e in enumerate(errs)]
    recs.append({"method": "c", "scene": "s", "seed": 1, "final": True, "relmse": 2.0})
    recs.append({"method": "a", "scene": "s", "seed": 0, "final": False, "relmse": 9.0})
    st = S.Study(recs)
    np.testing.assert_array_equal(st.seed_ratios("a", "b", "s"), [2.0, 8.0])
    np.testing.assert_array_equal(st.seed_ratios("a", "c", "s"), [2.0])
    with pytest.raises(KeyError, match="no final records"):
        st.seed_ratios("a", "d", "s")


def test_merged_study_compares_a_method_run_on_one_scene_only():
    """A method run on one scene (merged in from a second study) is compared with that scene's
    baseline, and has no ratio -- and raises no empty-mean warning -- on the scene it did not run on."""
    def recs(method, scene, err):
        return [{"method": method, "scene": scene, "seed": 0, "final": True, "relmse": err}]
    both = S.Study(recs("a", "s", 1.0) + recs("a", "t", 2.0) + recs("b", "s", 0.5) + recs("b", "t", 0.5),
                   images={("a", "s", 0): np.zeros(1)})
    one = S.Study(recs("c", "t", 0.25), images={("c", "t", 0): np.ones(1)})
    st = both.merge(one)
    with warnings.catch_warnings():
        warnings.simplefilter("error")          # numpy's empty-mean RuntimeWarning fails the test
        r = st.equal_time_ratios("a")
    assert r == {("a", "s"): 1.0, ("b", "s"): 2.0, ("a", "t"): 1.0, ("b", "t"): 4.0, ("c", "t"): 8.0}
    assert set(st.images) == {("a", "s", 0), ("c", "t", 0)} and len(both.records) == 4


def test_csv_has_every_column(serial, tmp_path):
    path = serial.to_csv(tmp_path / "r.csv")
    rows = list(csv.DictReader(open(path)))
    assert len(rows) == len(serial.records)
    assert {"relmse", "seconds", "t_trace", "t_shift", "t_reconstruct"} <= set(rows[0])
    assert float(rows[0]["relmse"]) == serial.records[0]["relmse"]


def test_method_specs_and_executor_names():
    m = S.Method.parse("gpt+l1")
    assert (m.label, m.estimator, m.solver) == ("gpt+l1", "gpt", "l1")
    assert S.Method.parse("gpt", solver="l2").label == "gpt+l2"
    # integrator options ride in the spec; numbers become numbers, module:Class keeps its colon
    m = S.Method.parse("bre:kernel=2d:neighbors=16:alpha=0.9")
    assert (m.label, m.estimator) == ("bre:kernel=2d:neighbors=16:alpha=0.9", "bre")
    assert m.options == (("kernel", "2d"), ("neighbors", 16), ("alpha", 0.9))
    m = S.Method.parse("gdlearn.teaching.toy:ToyGradient:seed_offset=3+l1")
    assert (m.estimator, m.solver, m.options) == ("gdlearn.teaching.toy:ToyGradient", "l1", (("seed_offset", 3),))
    assert isinstance(get_executor("serial"), SerialExecutor)
    assert get_executor("local:3").max_workers == 3
    with pytest.raises(ValueError, match="unknown executor"):
        get_executor("cloud")


def test_compare_command_on_the_toy(tmp_path, capsys):
    from gdlearn.commands import compare
    p = argparse.ArgumentParser()
    compare.add_parser(p.add_subparsers())
    args = p.parse_args(["compare", "toy:12x8", "--methods", "toy-pt,toy-gpt", "--passes", "8",
                         "--seeds", "2", "--snapshots", "3", "--executor", "serial",
                         "--csv", str(tmp_path / "c.csv"), "--plot", str(tmp_path / "c.png")])
    assert args.func(args) == 0
    out = capsys.readouterr().out
    assert "toy-pt" in out and "toy-gpt" in out and "1.00x" in out
    rows = list(csv.DictReader(open(tmp_path / "c.csv")))
    assert len(rows) == 2 * 2 * 3 and (tmp_path / "c.png").stat().st_size > 10_000


def test_scene_file_with_the_path_tracer():
    """The real road: a scene file with -D res=8, the registry's 'pt', deterministic per seed."""
    from pathlib import Path
    from gdlearn.commands.compare import _defines

    path = str(Path(__file__).parent.parent / "scenes" / "cornell-box.xml")
    scene = S.SceneFile(path, _defines(["res=8"]))
    a = S.equal_time(["pt"], scene, passes=3, seeds=[4], count=2, executor="serial")
    b = S.equal_time(["pt"], scene, passes=3, seeds=[4], count=2, executor="serial")
    img = a.images[("pt", "cornell-box", 4)]
    assert img.shape == (8, 8, 3) and img.mean() > 0
    np.testing.assert_array_equal(img, b.images[("pt", "cornell-box", 4)])
    assert a.records[-1]["t_trace"] > 0 and a.records[-1]["compile_seconds"] >= 0
    with pytest.raises(SystemExit, match="NAME=VALUE"):
        _defines(["res"])


def test_seed_images_are_one_method_and_scene_in_seed_order():
    img = {(m, s, k): np.full((2, 2, 3), 10.0 * k + (m == "b") + 100 * (s == "y"))
           for m in ("a", "b") for s in ("x", "y") for k in (2, 0, 1)}
    st = S.Study([], img)
    assert [float(i[0, 0, 0]) for i in st.seed_images("b", "x")] == [1.0, 11.0, 21.0]
    assert st.seed_images("c", "x") == []
