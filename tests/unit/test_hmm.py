"""The trajectory HMM of Sect. 5.4: observation model, transitions, filtering, model files."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from knowledge.errors import ModelError, NotFittedError
from knowledge.learning.hmm import HMMFilter, PlaceHMM, kl_likelihood, move_transitions

CLASSES = ("room", "corridor", "doorway")


def fitted(counts: np.ndarray | None = None, **params: object) -> PlaceHMM:
    """An HMM whose class means are sharp: room (0.8, 0.15, 0.05), corridor, doorway alike."""
    rng = np.random.default_rng(0)
    H, y = [], []
    for i, c in enumerate(CLASSES):
        base = np.full(3, 0.1)
        base[i] = 0.8
        H.append(rng.dirichlet(base * 50, size=60))
        y += [c] * 60
    if counts is None:
        counts = np.array([[900, 5, 50], [5, 800, 60], [55, 60, 300]])
    return PlaceHMM(**params).fit(np.vstack(H), np.array(y), classes=CLASSES, move_counts=counts)  # type: ignore[arg-type]


def test_init_stores_parameters_and_fit_returns_self() -> None:
    hmm = PlaceHMM(m=20, n_moves=10, stay=0.9)
    assert hmm.get_params()["m"] == 20 and hmm.get_params()["stay"] == 0.9
    assert not [k for k in vars(hmm) if k.endswith("_")]
    h = fitted()
    assert h.means_.shape == (3, 3) and h.move_.shape == (3, 3)
    assert list(h.classes_) == list(CLASSES)
    np.testing.assert_allclose(h.move_.sum(axis=1), 1.0)
    np.testing.assert_allclose(h.means_.sum(axis=1), 1.0)
    # the book's m = 50 observations per class
    assert h.n_observations_.tolist() == [50, 50, 50]
    assert PlaceHMM(m=None).fit(
        np.eye(3), np.array(CLASSES), classes=CLASSES, move_counts=np.eye(3)
    ).n_observations_.tolist() == [1, 1, 1]


def test_unfitted_hmm_says_so() -> None:
    with pytest.raises(NotFittedError, match="fit"):
        PlaceHMM().filter(np.ones((2, 3)) / 3, np.zeros(2, bool))
    with pytest.raises(NotFittedError):
        HMMFilter(PlaceHMM())


def test_bad_fit_input_is_refused() -> None:
    with pytest.raises(ValueError, match="no observation of class 'doorway'"):
        PlaceHMM().fit(np.eye(3)[:2], np.array(["room", "corridor"]), classes=CLASSES, move_counts=np.eye(3))
    with pytest.raises(ValueError, match="move_counts"):
        PlaceHMM().fit(np.eye(3), np.array(CLASSES), classes=CLASSES, move_counts=np.eye(2))
    with pytest.raises(ValueError, match="stay"):
        PlaceHMM(stay=0.0).fit(np.eye(3), np.array(CLASSES), classes=CLASSES, move_counts=np.eye(3))


def test_likelihood_is_eq_5_4() -> None:
    means = np.array([[0.7, 0.2, 0.1], [0.2, 0.7, 0.1], [0.3, 0.3, 0.4]])
    z = np.array([0.6, 0.3, 0.1])
    got = kl_likelihood(z, means, eps=0.0)
    want = [math.exp(-sum(z[k] * math.log(z[k] / means[y, k]) for k in range(3))) for y in range(3)]
    np.testing.assert_allclose(got, want, rtol=1e-12)
    # an observation equal to a class's mean has likelihood 1 there, less elsewhere
    own = kl_likelihood(means, means, eps=0.0)
    np.testing.assert_allclose(np.diag(own), 1.0)
    assert (own[~np.eye(3, dtype=bool)] < 1.0).all()
    # zero bins do not make it infinite
    assert np.isfinite(kl_likelihood(np.array([1.0, 0.0, 0.0]), np.eye(3))).all()


@settings(max_examples=200, deadline=None)
@given(
    arrays(np.float64, (7, 3), elements=st.floats(0.0, 1.0)),
    arrays(np.bool_, (7,)),
)
def test_filtered_beliefs_are_distributions(raw: np.ndarray, moved: np.ndarray) -> None:
    for observation in ("kl", "histogram"):
        bel = fitted(observation=observation).filter(raw, moved)
        assert bel.shape == (7, 3)
        assert np.isfinite(bel).all() and (bel >= 0).all()
        np.testing.assert_allclose(bel.sum(axis=1), 1.0, rtol=1e-9)


@settings(max_examples=100, deadline=None)
@given(arrays(np.float64, (6, 3), elements=st.floats(0.01, 1.0)), arrays(np.bool_, (6,)))
def test_identity_transitions_and_uninformative_observations_keep_the_prior(
    raw: np.ndarray, moved: np.ndarray
) -> None:
    # every class has the same mean histogram: no observation favours a class
    hmm = PlaceHMM(m=None, prior=0.0).fit(
        np.full((3, 3), 1 / 3), np.array(CLASSES), classes=CLASSES, move_counts=np.eye(3) * 10
    )
    np.testing.assert_array_equal(hmm.move_, np.eye(3))
    bel = hmm.filter(raw, moved)
    np.testing.assert_allclose(bel, np.full((6, 3), 1 / 3), atol=1e-12)


def test_the_histogram_observation_model_is_the_tempered_histogram() -> None:
    hmm = fitted(observation="histogram", temper=0.5, eps=0.0)
    z = np.array([0.6, 0.3, 0.1])
    np.testing.assert_allclose(hmm.likelihood(z), np.sqrt(z))
    # with Stay and a uniform belief, one update is the normalised tempered histogram
    np.testing.assert_allclose(hmm.step(hmm.prior_, z, moved=False), np.sqrt(z) / np.sqrt(z).sum())
    with pytest.raises(ValueError, match="observation"):
        PlaceHMM(observation="vibes").fit(
            np.eye(3), np.array(CLASSES), classes=CLASSES, move_counts=np.eye(3)
        )


@pytest.mark.parametrize("observation", ["kl", "histogram"])
def test_a_steady_class_wins_and_one_outlier_does_not_flip_it(observation: str) -> None:
    hmm = fitted(observation=observation)
    room, corridor = np.array([0.8, 0.15, 0.05]), np.array([0.15, 0.8, 0.05])
    obs = np.array([room] * 10 + [corridor] + [room] * 3)
    bel = hmm.filter(obs, np.ones(len(obs), bool))
    assert bel[0].argmax() == 0
    assert (bel.argmax(axis=1) == 0).all()  # the lone corridor scan is outvoted by the history
    # the raw decision would have flipped
    assert obs.argmax(axis=1)[10] == 1
    # and a lasting change wins after a few scans
    obs2 = np.array([room] * 10 + [corridor] * 10)
    assert hmm.filter(obs2, np.ones(20, bool))[-1].argmax() == 1


def test_stay_keeps_the_class_and_move_lets_it_change() -> None:
    hmm = fitted()
    room, corridor = np.array([0.8, 0.15, 0.05]), np.array([0.15, 0.8, 0.05])
    b = hmm.step(hmm.prior_, room, moved=False)
    stay = hmm.step(b, corridor, moved=False)
    move = hmm.step(b, corridor, moved=True)
    assert move[1] > stay[1]  # under Move a class change is more likely a priori
    np.testing.assert_allclose(hmm.stay_, np.eye(3))


def test_the_agent_filter_moves_after_move_min() -> None:
    hmm = fitted(move_min=0.2)
    f = HMMFilter(hmm)
    np.testing.assert_allclose(f.belief, 1 / 3)
    room = np.array([0.8, 0.15, 0.05])
    seen: list[bool] = []
    real_step = hmm.step

    def spy(belief: np.ndarray, histogram: np.ndarray, moved: bool) -> np.ndarray:
        seen.append(moved)
        return real_step(belief, histogram, moved)

    hmm.step = spy  # type: ignore[method-assign,assignment]
    for x in (0.0, 0.1, 0.19, 0.25, 0.3, 0.46):
        f.update(room, (x, 0.0))
    assert seen == [False, False, False, True, False, True]
    f.reset()
    np.testing.assert_allclose(f.belief, 1 / 3)


def test_move_transitions_count_class_changes_in_a_labelled_map() -> None:
    # two 4 m x 4 m rooms side by side at 0.05 m: room | corridor, no wall between
    labels = np.zeros((80, 160), np.uint8)
    labels[:, :80], labels[:, 80:] = 1, 2
    free = np.ones_like(labels, bool)
    free[[0, -1], :] = free[:, [0, -1]] = False
    counts = move_transitions([labels], [0.05], [free], [1, 2], np.random.default_rng(1), n_moves=1000)
    assert counts.sum() == 1000
    # staying is far more likely than crossing (only moves starting within 0.5 m of the line cross)
    assert counts[0, 0] > 5 * counts[0, 1] > 0 and counts[1, 1] > 5 * counts[1, 0] > 0
    # a map of one class only ever stays
    one = move_transitions(
        [np.ones((40, 40), np.uint8)],
        [0.05],
        [np.ones((40, 40), bool)],
        [1, 2],
        np.random.default_rng(2),
        n_moves=50,
    )
    assert one.tolist() == [[50, 0], [0, 0]]
    with pytest.raises(ValueError, match="no labelled free cell"):
        move_transitions(
            [np.zeros((4, 4), np.uint8)], [0.05], [np.ones((4, 4), bool)], [1], np.random.default_rng(0)
        )


def test_the_hmm_travels_in_the_model_file(tmp_path: Path) -> None:
    pytest.importorskip("knowledge.places.features")
    from functools import partial

    from knowledge.learning.boosting import GeneralizedAdaBoost
    from knowledge.learning.decision_list import DecisionList
    from knowledge.places.model import PlaceModel, ScanParams

    rng = np.random.default_rng(3)
    X = rng.normal(size=(90, 4))
    y = np.array(CLASSES)[np.argmax(X[:, :3], axis=1)]
    dl = DecisionList(partial(GeneralizedAdaBoost, n_rounds=3)).fit(X, y, classes=CLASSES)
    model = PlaceModel.from_decision_list(dl, ["A.1", "A.2", "A.5", "A.6"], scan=ScanParams(360, 30.0))
    assert model.hmm is None
    hmm = fitted()
    with_hmm = model.with_hmm(hmm)
    assert model.hmm is None  # the original is unchanged
    path = with_hmm.save(tmp_path / "m.npz")
    back = PlaceModel.load(path).hmm
    assert back is not None
    for name in ("means_", "move_", "stay_", "move_counts_", "n_observations_"):
        np.testing.assert_array_equal(getattr(back, name), getattr(hmm, name))
    assert back.get_params() == hmm.get_params()
    # a damaged HMM is refused on loading, naming what to do
    with np.load(path, allow_pickle=False) as z:
        arrays = {k: z[k] for k in z.files}
    arrays["extra.hmm_move"] = arrays["extra.hmm_move"] * 2
    bad = tmp_path / "bad.npz"
    np.savez(bad, **arrays)
    with pytest.raises(ModelError, match="HMM is damaged"):
        PlaceModel.load(bad)
    # an HMM over other classes does not fit
    other = PlaceHMM(m=None).fit(np.eye(2), np.array(["a", "b"]), classes=("a", "b"), move_counts=np.eye(2))
    with pytest.raises(ValueError, match="classes"):
        model.with_hmm(other)


def test_stored_parameters_out_of_range_are_refused_on_loading() -> None:
    hmm = fitted(observation="histogram")
    meta, arrays = hmm.to_arrays()
    again = PlaceHMM.from_arrays(meta, arrays)
    assert again.get_params() == hmm.get_params()
    np.testing.assert_allclose(again.move_, hmm.move_)
    # a misspelt observation used to load and fall back to eq. 5.4 without a word
    bad = {**meta, "params": {**meta["params"], "observation": "histgram"}}
    with pytest.raises(ValueError, match="observation"):
        PlaceHMM.from_arrays(bad, arrays)
