"""``[localization]`` in the pipeline: the tracker corrects the odometry before the graph
and the local map see the pose; configuration and recorded parameters carry it."""

from __future__ import annotations

import math

import numpy as np
import pytest
from support.localization_world import ANGLES, RANGE_MAX, drifting_odometry, path, scans, world

from agent.config import load_config
from agent.core.pipeline import Pipeline, PipelineParams, graph_message
from drivers.messages import LaserScan, Pose2D
from knowledge.errors import ConfigError
from knowledge.localization.se2 import compose
from knowledge.localization.tracking import TrackingParams
from knowledge.localization.trajectory import ate
from knowledge.places.model import PlaceModel, default_model_path


def test_the_configuration_turns_tracking_on_and_recordings_keep_it() -> None:
    assert load_config(table={}, env={}).localization.tracking is False
    assert PipelineParams.from_config(load_config(table={}, env={})).localization is None
    cfg = load_config(table={"localization": {"tracking": True, "beam_step": 3}}, env={})
    params = PipelineParams.from_config(cfg)
    assert params.localization == TrackingParams(beam_step=3)
    assert params.tracking_lag == 3  # the tracker runs on its own thread by default
    assert PipelineParams.from_table(params.to_table()) == params
    inline = PipelineParams.from_config(
        load_config(table={"localization": {"tracking": True, "lag": 0}}, env={})
    )
    assert inline.tracking_lag == 0 and "tracking_lag" not in inline.to_table()
    assert PipelineParams.from_table(inline.to_table()) == inline
    # a recording made before the odometry prior replays without it
    old = params.to_table()
    for key in ("prior_translation", "prior_rotation"):
        del old["localization"][key]
    assert PipelineParams.from_table(old).localization == TrackingParams(
        beam_step=3, prior_translation=0.0, prior_rotation=0.0
    )
    # one made before the incremental field replays with the window remade as it ran
    assert params.localization is not None and params.localization.field == "incremental"
    old = params.to_table()
    del old["localization"]["field"]
    assert PipelineParams.from_table(old).localization == TrackingParams(beam_step=3, field="window")
    with pytest.raises(ConfigError, match="tracking_lag"):
        PipelineParams.from_table({**params.to_table(), "tracking_lag": -1})
    with pytest.raises(ConfigError, match="lag"):
        load_config(table={"localization": {"tracking": True, "lag": 1.5}}, env={})
    with pytest.raises(ConfigError, match="unknown key 'trackin'"):
        load_config(table={"localization": {"trackin": True}}, env={})


def test_tracking_in_the_pipeline_corrects_drifting_odometry() -> None:
    g = world()
    truth = path(0.1)
    R = scans(g, truth)
    odo = compose(truth[0], drifting_odometry(truth, drift=0.03, scale=1.04))  # starts at the true pose
    model = PlaceModel.load(default_model_path())
    on = Pipeline(model, PipelineParams(localization=TrackingParams(), people=_no_people()))
    off = Pipeline(model, PipelineParams(people=_no_people()))
    got_on, got_off = [], []
    for i in range(len(truth)):
        scan = LaserScan(
            float(i), i, "laser", float(ANGLES[0]), float(ANGLES[1] - ANGLES[0]), RANGE_MAX, R[i]
        )
        pose = Pose2D(*odo[i], stamp=float(i))
        a, b = on.process(scan, pose), off.process(scan, pose)
        got_on.append((a.pose.x, a.pose.y, a.pose.theta))
        got_off.append((b.pose.x, b.pose.y, b.pose.theta))
        assert a.pose.frame_id == "map" and a.correction is not None
        assert b.pose.frame_id == "odom" and b.correction is None
    err_on = np.hypot(*(np.array(got_on)[:, :2] - truth[:, :2]).T)
    err_off = np.hypot(*(np.array(got_off)[:, :2] - truth[:, :2]).T)
    assert err_off.max() > 2.0 and err_on.max() < 0.25
    assert ate(truth, np.array(got_on))[0].rmse < 0.1 < ate(truth, np.array(got_off))[0].rmse
    # the graph lives in the corrected frame and says so
    assert on.messages()[0]["frame_id"] == "map" and off.messages()[0]["frame_id"] == "odom"
    assert graph_message(on.state_document(), 0.0)["frame_id"] == "odom"  # the default stays
    assert math.isfinite(float(a.correction[2]))


@pytest.mark.parametrize("lag", [1, 3])
def test_the_tracker_on_its_own_thread_corrects_scan_k_with_scan_k_minus_lag(lag: int) -> None:
    """Off the per-scan path, the tracker's result is used ``lag`` scans later: exactly the
    inline tracker's correction of scan k − lag, so a replay reproduces a live run."""
    g = world()
    truth = path(0.1)
    R = scans(g, truth)
    odo = compose(truth[0], drifting_odometry(truth, drift=0.03, scale=1.04))
    model = PlaceModel.load(default_model_path())
    inline = Pipeline(model, PipelineParams(localization=TrackingParams(), people=_no_people()))
    runs = [
        Pipeline(model, PipelineParams(localization=TrackingParams(), people=_no_people(), tracking_lag=lag))
        for _ in range(2)
    ]
    ref, got = [], [[], []]
    try:
        for i in range(len(truth)):
            scan = LaserScan(
                float(i), i, "laser", float(ANGLES[0]), float(ANGLES[1] - ANGLES[0]), RANGE_MAX, R[i]
            )
            pose = Pose2D(*odo[i], stamp=float(i))
            ref.append(inline.process(scan, pose).correction)
            for run, out in zip(runs, got, strict=True):
                r = run.process(scan, pose)
                assert r.pose.frame_id == "map"
                out.append((r.correction, (r.pose.x, r.pose.y, r.pose.theta)))
    finally:
        for run in runs:
            run.close()
    for out in got:
        for k, (corr, _) in enumerate(out):
            expected = np.zeros(3) if k < lag else ref[k - lag]
            np.testing.assert_array_equal(corr, expected)
    # two runs of the same input: the same poses, whatever the thread's timing was
    assert [p for _, p in got[0]] == [p for _, p in got[1]]
    err = np.hypot(*(np.array([p for _, p in got[0]])[:, :2] - truth[:, :2]).T)
    assert err.max() < 0.3  # a few scans' worth of drift more than inline at most
    assert len(truth) - lag <= len(runs[0].tracking_ms) <= len(truth)  # close() drops what had not started


def _no_people():  # type: ignore[no-untyped-def]
    from agent.core.pipeline import PeopleParams

    return PeopleParams(enabled=False)


def test_a_scan_the_tracker_fails_on_costs_only_its_own_match() -> None:
    """On the tracker's thread an exception (here: one scan) is counted and the correction
    before it stands; the scan that collects the result is processed like any other."""
    g = world()
    truth = path(0.1)[:40]
    R = scans(g, truth)
    odo = compose(truth[0], drifting_odometry(truth, drift=0.03, scale=1.04))
    model = PlaceModel.load(default_model_path())
    pipe = Pipeline(model, PipelineParams(localization=TrackingParams(), people=_no_people(), tracking_lag=2))
    assert pipe.tracker is not None
    real = pipe.tracker.update
    calls = {"n": 0}

    def flaky(*args, **kw):  # type: ignore[no-untyped-def]
        calls["n"] += 1
        if calls["n"] == 10:
            raise ValueError("a bad scan")
        return real(*args, **kw)

    pipe.tracker.update = flaky  # type: ignore[method-assign]
    results = []
    try:
        for i in range(len(truth)):
            scan = LaserScan(
                float(i), i, "laser", float(ANGLES[0]), float(ANGLES[1] - ANGLES[0]), RANGE_MAX, R[i]
            )
            results.append(pipe.process(scan, Pose2D(*odo[i], stamp=float(i))))
    finally:
        pipe.close()
    assert len(results) == len(truth) and pipe.scans == len(truth)
    assert pipe.tracking_errors == 1 and pipe.last_tracking_error == "ValueError: a bad scan"
    # scan 11 collects scan 9's failed match: it keeps scan 8's correction
    np.testing.assert_array_equal(results[11].correction, results[10].correction)
