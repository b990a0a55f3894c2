"""People in laser scans (book chapter 8, appendix C).

* :mod:`~knowledge.people.segmentation` — jump-distance segmentation (15 cm);
* :mod:`~knowledge.people.features` — the 14 segment features C.1–C.14;
* :mod:`~knowledge.people.detector` — the boosted leg detector (generalized AdaBoost, T = 100),
  per-segment and per-beam person labels, model files;
* :mod:`~knowledge.people.pairing` — legs → people;
* :mod:`~knowledge.people.tracking` — constant-velocity Kalman tracks with stable ids;
* :mod:`~knowledge.people.pipeline` — all of the above, one scan at a time;
* :mod:`~knowledge.people.dataset` — the legs data and its train/test protocol;
* :mod:`~knowledge.people.evaluation` — confusion matrices in the form of Tables 8.1–8.3.
"""
