"""Benchmark: our boosting vs scikit-learn's AdaBoost with stumps, same data, same T.

Target (DESIGN.md): training at least 5× faster than
``AdaBoostClassifier(estimator=DecisionTreeClassifier(max_depth=1), n_estimators=T)`` at equal
test accuracy (±0.5 %). Both boosters start from uniform weights here (``balanced=False``; the
book's class-balanced start is our default), both run single-threaded in this process.
The speed-up is measured in CPU seconds of this process (``time.process_time``), which other
jobs on a shared machine disturb much less than wall-clock time; both are reported.

    python -m tools.bench_boosting [--n-train 30000] [--features 300] [--rounds 100]
                                   [--json | --json-file FILE]

scikit-learn is a bench-only dependency (``pip install -e '.[bench]'``); it is imported lazily
and the baseline is skipped with a message when it is missing. :func:`run` takes any
``(X, y)`` so real place features can be benchmarked the same way.
"""

from __future__ import annotations

import argparse
import contextlib
import importlib
import inspect
import sys
import time
import tracemalloc
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np
import numpy.typing as npt

from agent.commands.options import add_json_file_option, add_json_option, emit_result
from knowledge.learning.boosting import GeneralizedAdaBoost
from knowledge.learning.weak import SortedFeatures


def make_data(
    n_samples: int = 60_000, n_features: int = 300, *, seed: int = 0
) -> tuple[npt.NDArray[np.float32], npt.NDArray[np.bool_]]:
    """A place-like binary problem: ``(n_samples, n_features)`` float32 and labels.

    20 informative columns (Gaussian) drive the label through a noisy non-linear score;
    the rest are distractors of the kinds scan features produce: monotone transforms of
    informative columns (log-normal "lengths"), integer counts (many ties), clipped ranges
    and pure noise.
    """
    rng = np.random.default_rng(seed)
    n_inf = min(20, n_features)
    Z = rng.normal(size=(n_samples, n_inf))
    score = (
        Z[:, :5].sum(axis=1)
        + 1.5 * np.abs(Z[:, 5:10]).sum(axis=1)
        - 1.5 * 0.798 * 5  # centre |z| terms (E|z| ≈ 0.798)
        + np.where(Z[:, 10] * Z[:, 11] > 0, 1.0, -1.0)
        + 0.5 * np.sin(2.0 * Z[:, 12:n_inf]).sum(axis=1)
        + rng.normal(scale=1.5, size=n_samples)
    )
    y = score > np.quantile(score, 0.6)  # 40 % positives
    cols = [Z]
    rest = n_features - n_inf
    kinds = np.arange(rest) % 4
    for k in kinds:
        if k == 0:
            cols.append(
                np.exp(0.5 * Z[:, rng.integers(n_inf), None] + rng.normal(scale=0.8, size=(n_samples, 1)))
            )
        elif k == 1:
            cols.append(rng.poisson(rng.uniform(0.5, 6.0), size=(n_samples, 1)).astype(float))
        elif k == 2:
            cols.append(np.minimum(rng.exponential(rng.uniform(1, 8), size=(n_samples, 1)), 5.0))
        else:
            cols.append(rng.normal(size=(n_samples, 1)))
    X = np.hstack(cols)[:, rng.permutation(n_features)].astype(np.float32)
    return X, y


def scan_data(n_samples: int, *, seed: int = 0) -> tuple[npt.NDArray[np.float32], npt.NDArray[np.bool_]]:
    """Real place features (every default feature name) of synthetic 360° scans; y = "room"."""
    from knowledge.places.features import FeatureExtractor, default_feature_names
    from knowledge.places.features.synthetic import KINDS, random_scans

    ranges, kind = random_scans(n_samples, rng=np.random.default_rng(seed))
    X = FeatureExtractor(default_feature_names(), max_range=30.0)(ranges)
    return np.asarray(X, dtype=np.float32), kind == KINDS.index("room")


def _sklearn_booster(n_rounds: int) -> Any:
    from sklearn.ensemble import AdaBoostClassifier
    from sklearn.tree import DecisionTreeClassifier

    kwargs: dict[str, Any] = {"estimator": DecisionTreeClassifier(max_depth=1), "n_estimators": n_rounds}
    if "algorithm" in inspect.signature(AdaBoostClassifier).parameters:
        kwargs["algorithm"] = "SAMME"  # discrete AdaBoost; SAMME.R is gone in newer releases
    return AdaBoostClassifier(**kwargs)


def run(
    X: npt.ArrayLike | None = None,
    y: npt.ArrayLike | None = None,
    X_test: npt.ArrayLike | None = None,
    y_test: npt.ArrayLike | None = None,
    *,
    n_rounds: int = 100,
    n_train: int = 30_000,
    n_features: int = 300,
    baseline: bool = True,
    scans: bool = False,
) -> dict[str, Any]:
    """Train both boosters on ``X, y`` (synthetic if None), score on ``X_test, y_test``.

    Returns times in seconds, test accuracies, the speed-up ``sklearn_fit_s / ours_fit_s``
    and our memory: the kept sort and the peak allocated during a (short) fit. With
    ``scans`` the synthetic data are the place features of synthetic scans instead.
    """
    generated = X is None or y is None
    if generated:
        Xa, ya = scan_data(2 * n_train) if scans else make_data(2 * n_train, n_features)
        X, y, X_test, y_test = Xa[:n_train], ya[:n_train], Xa[n_train:], ya[n_train:]
    Xtr, ytr = np.asarray(X), np.asarray(y).astype(bool)
    Xte = Xtr if X_test is None else np.asarray(X_test)
    yte = ytr if y_test is None else np.asarray(y_test).astype(bool)
    result: dict[str, Any] = {
        "n_train": int(Xtr.shape[0]),
        "n_features": int(Xtr.shape[1]),
        "n_rounds": n_rounds,
        "n_test": int(Xte.shape[0]),
        "data": ("scan features" if scans else "synthetic") if generated else "given",
    }
    with _single_thread():
        ours = GeneralizedAdaBoost(n_rounds, balanced=False)
        result["ours_fit_s"], result["ours_fit_cpu_s"] = _timed(lambda: ours.fit(Xtr, ytr))
        result["ours_predict_s"], _ = _timed(lambda: ours.predict(Xte))
        result["ours_accuracy"] = float(np.mean(ours.predict(Xte) == yte))
        result["ours_rounds"] = ours.n_rounds_

        tracemalloc.start()
        sf = SortedFeatures(Xtr)
        GeneralizedAdaBoost(3, balanced=False).fit(Xtr, ytr, presorted=sf)
        result["ours_peak_mb"] = tracemalloc.get_traced_memory()[1] / 1e6
        tracemalloc.stop()
        result["ours_sort_mb"] = sf.nbytes / 1e6
        del sf

        if not baseline:
            return result
        try:
            sk = _sklearn_booster(n_rounds)
        except ImportError:
            result["sklearn"] = "scikit-learn is not installed: pip install -e '.[bench]' to compare"
            return result
        result["sklearn_fit_s"], result["sklearn_fit_cpu_s"] = _timed(lambda: sk.fit(Xtr, ytr))
        result["sklearn_predict_s"], _ = _timed(lambda: sk.predict(Xte))
        result["sklearn_accuracy"] = float(np.mean(sk.predict(Xte) == yte))
        result["sklearn_rounds"] = len(sk.estimators_)
    result["speedup"] = result["sklearn_fit_cpu_s"] / result["ours_fit_cpu_s"]
    result["speedup_wall"] = result["sklearn_fit_s"] / result["ours_fit_s"]
    result["accuracy_diff"] = result["ours_accuracy"] - result["sklearn_accuracy"]
    return result


def _timed(fn: Callable[[], object]) -> tuple[float, float]:
    """Wall-clock and CPU seconds of ``fn()``."""
    w0, c0 = time.perf_counter(), time.process_time()
    fn()
    return time.perf_counter() - w0, time.process_time() - c0


def _single_thread() -> contextlib.AbstractContextManager[object]:
    """Limit BLAS/OpenMP pools to one thread (if threadpoolctl is there) so both run alike."""
    try:
        threadpoolctl = importlib.import_module("threadpoolctl")  # comes with scikit-learn
    except ImportError:
        return contextlib.nullcontext()
    limits: contextlib.AbstractContextManager[object] = threadpoolctl.threadpool_limits(1)
    return limits


def format_result(r: dict[str, Any]) -> str:
    lines = [
        f"boosting benchmark: {r['n_train']} training examples x {r['n_features']} features "
        f"({r['data']}), T = {r['n_rounds']}",
        f"  ours     fit {r['ours_fit_s']:7.2f} s ({r['ours_fit_cpu_s']:.2f} s CPU)  predict {r['ours_predict_s']:.3f} s  "
        f"test accuracy {100 * r['ours_accuracy']:.2f} %  rounds {r['ours_rounds']}",
        f"           memory: sort {r['ours_sort_mb']:.0f} MB, peak during fit {r['ours_peak_mb']:.0f} MB",
    ]
    if "sklearn_fit_s" in r:
        lines += [
            f"  sklearn  fit {r['sklearn_fit_s']:7.2f} s ({r['sklearn_fit_cpu_s']:.2f} s CPU)  predict {r['sklearn_predict_s']:.3f} s  "
            f"test accuracy {100 * r['sklearn_accuracy']:.2f} %  rounds {r['sklearn_rounds']}",
            f"  speed-up {r['speedup']:.1f}x in CPU time, {r['speedup_wall']:.1f}x wall (target >= 5x); accuracy difference "
            f"{100 * r['accuracy_diff']:+.2f} % (target within +-0.5 %)",
        ]
    elif "sklearn" in r:
        lines.append(f"  baseline skipped: {r['sklearn']}")
    return "\n".join(lines)


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="python -m tools.bench_boosting", description=__doc__.split("\n")[0]
    )
    parser.add_argument("--n-train", type=int, default=30_000, help="training examples (as many for testing)")
    parser.add_argument("--features", type=int, default=300)
    parser.add_argument("--rounds", type=int, default=100, help="T, for both boosters")
    parser.add_argument(
        "--scans", action="store_true", help="use the place features of synthetic scans (slow to compute)"
    )
    parser.add_argument("--no-baseline", action="store_true", help="skip scikit-learn")
    add_json_option(parser)
    add_json_file_option(parser)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    r = run(
        n_rounds=args.rounds,
        n_train=args.n_train,
        n_features=args.features,
        baseline=not args.no_baseline,
        scans=args.scans,
    )
    emit_result(args, r, format_result)
    return 0


if __name__ == "__main__":
    sys.exit(main())
