"""The shipped confidence model's coefficients (see `semloc.decision.ConfidenceModel`).

Written by `benchmarks/calibrate_confidence.py --write`; data, not I/O: the core reads no files.
"""

SHIPPED = {
    "evidence_bias": -5.437578386102801,
    "evidence_weights": {
        "pairs": 0.6988589779374301,
        "rejected_share": -1.32102677408673,
        "residual": 0.0,
        "fitness": 3.225871960500866,
        "support": -0.10537524482906564,
        "conflict_share": -2.7670869379856455,
    },
    "confidence_bias": 2.5245075603145875,
    "confidence_evidence": 1.4417116112495263,
    "confidence_rival": -4.519785622599907,
    "min_confidence": 0.744630984451111,
    "fitted_by": "benchmarks/calibrate_confidence.py --sequences 3 --starts 4 --holdout-sequences "
    "1 --write --figure docs/img/reliability.png",
    "data": "semloc attempts of the benchmark protocol: seed 1, 3 sequences, 4 starts, map kinds "
    "reconstruction, cad, dynamic; 524 hypotheses",
}
