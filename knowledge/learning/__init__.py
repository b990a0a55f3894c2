"""The learners the place and people classifiers share (book Ch. 3 and Sect. 5.4).

Discrete and generalized AdaBoost over threshold stumps (:mod:`~knowledge.learning.boosting`,
:mod:`~knowledge.learning.weak`), the sequential decision list of binary classifiers for more
than two classes (:mod:`~knowledge.learning.decision_list`), the hidden Markov model that
filters a class histogram along a trajectory (:mod:`~knowledge.learning.hmm`) and the scores
(accuracy, balanced accuracy, confusion) every evaluation reports
(:mod:`~knowledge.learning.metrics`). Pure numpy/numba; nothing here knows what a place is.
"""
