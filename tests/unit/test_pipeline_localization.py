"""``[localization]`` in the pipeline: the tracker corrects the odometry before the graph
and the local map see the pose; configuration and recorded parameters carry it."""

from __future__ import annotations

import math

import numpy as np
import pytest
from support.localization_world import ANGLES, RANGE_MAX, drifting_odometry, path, scans, world

from agent.config import load_config
from agent.core.pipeline import Pipeline, PipelineParams, graph_message, smooth_correction
from drivers.messages import LaserScan, Pose2D
from knowledge.errors import ConfigError
from knowledge.localization.se2 import compose, inverse
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
    states: list[str] = []
    for i in range(len(truth)):
        scan = LaserScan(
            float(i), i, "laser", float(ANGLES[0]), float(ANGLES[1] - ANGLES[0]), RANGE_MAX, R[i]
        )
        pose = Pose2D(*odo[i], stamp=float(i))
        a, b = on.process(scan, pose), off.process(scan, pose)
        got_on.append((a.pose.x, a.pose.y, a.pose.theta))
        got_off.append((b.pose.x, b.pose.y, b.pose.theta))
        assert a.pose.frame_id == "map" and a.correction is not None
        assert b.pose.frame_id == "odom" and b.correction is None and b.localization is None
        assert a.localization is not None  # how sure the pose is, after every scan
        states.append(a.localization.state)
    err_on = np.hypot(*(np.array(got_on)[:, :2] - truth[:, :2]).T)
    err_off = np.hypot(*(np.array(got_off)[:, :2] - truth[:, :2]).T)
    assert err_off.max() > 2.0 and err_on.max() < 0.25
    assert states.count("tracking") > 0.9 * len(states) and "lost" not in states
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


def _run(
    params: PipelineParams, truth: np.ndarray, R: np.ndarray, odo: np.ndarray, rate: float
) -> np.ndarray:
    pipe = Pipeline(PlaceModel.load(default_model_path()), params)
    out = []
    try:
        for i in range(len(truth)):
            scan = LaserScan(
                i / rate, i, "laser", float(ANGLES[0]), float(ANGLES[1] - ANGLES[0]), RANGE_MAX, R[i]
            )
            r = pipe.process(scan, Pose2D(*odo[i], stamp=i / rate))
            out.append((r.pose.x, r.pose.y, r.pose.theta))
    finally:
        pipe.close()
    return np.array(out)


def test_smoothing_keeps_each_match_s_noise_out_of_the_next_scans() -> None:
    """Scan k gets scan k − 3's correction: that match's own error (here the odometry's
    heading at each scan off by a few milliseconds of a turn, as a jittered stamp makes it)
    comes on top of scan k's. Smoothed over 0.25 s it averages out."""
    g = world()
    truth = path(0.1)
    R = scans(g, truth)
    rng = np.random.default_rng(3)
    odo = compose(truth[0], drifting_odometry(truth, drift=0.03, scale=1.04))
    odo[:, 2] += rng.normal(0.0, 0.02, len(odo))  # per-scan heading error, not accumulating
    raw = _run(
        PipelineParams(localization=TrackingParams(), people=_no_people(), tracking_lag=3),
        truth,
        R,
        odo,
        37.5,
    )
    smooth = _run(
        PipelineParams(
            localization=TrackingParams(), people=_no_people(), tracking_lag=3, tracking_smoothing=0.25
        ),
        truth,
        R,
        odo,
        37.5,
    )
    # heading errors against the truth
    err = {k: np.angle(np.exp(1j * (p[:, 2] - truth[:, 2]))) for k, p in (("raw", raw), ("smooth", smooth))}
    sd = {k: float(np.std(e[10:])) for k, e in err.items()}
    assert sd["smooth"] < 0.8 * sd["raw"], sd
    assert sd["smooth"] < 1.3 * 0.02  # about the odometry's own, where the raw is about √2 times it
    # recordings carry the setting; older ones had none
    p = PipelineParams(localization=TrackingParams(), tracking_lag=3, tracking_smoothing=0.25)
    assert PipelineParams.from_table(p.to_table()) == p
    old = p.to_table()
    del old["tracking_smoothing"]
    assert PipelineParams.from_table(old).tracking_smoothing == 0.0
    with pytest.raises(ConfigError, match="smoothing"):
        load_config(table={"localization": {"tracking": True, "smoothing": -1}}, env={})


def test_smoothing_moves_the_pose_part_of_the_way_and_takes_jumps_at_once() -> None:
    far = np.array([40.0, -25.0, 2.0])  # an odometry pose far from the odometry's origin
    applied = np.array([1.0, 2.0, 0.1])
    tau, dt = 0.25, 1 / 37.5
    a = 1 - math.exp(-dt / tau)
    # a small change (5 cm, 0.02 rad of the pose): the pose moves the fraction a of the way
    target_pose = compose(applied, far) + np.array([0.03, -0.04, 0.02])
    raw = compose(target_pose, inverse(far))
    got = compose(smooth_correction(applied, raw, far, dt, tau), far)
    before = compose(applied, far)
    np.testing.assert_allclose(got, before + a * (target_pose - before), atol=1e-9)
    # nothing smoothed with tau 0, a jump taken at once, and time never runs backwards
    np.testing.assert_array_equal(smooth_correction(applied, raw, far, dt, 0.0), raw)
    for step in ([0.3, 0.0, 0.0], [0.0, 0.0, 0.15]):
        jumped = compose(compose(applied, far) + np.array(step), inverse(far))
        np.testing.assert_allclose(smooth_correction(applied, jumped, far, dt, tau), jumped)
    np.testing.assert_allclose(smooth_correction(applied, raw, far, -1.0, tau), applied, atol=1e-12)
