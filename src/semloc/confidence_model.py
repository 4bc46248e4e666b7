"""The shipped confidence model's coefficients (see `semloc.decision.ConfidenceModel`).

Written by `benchmarks/calibrate_confidence.py --write`; data, not I/O: the core reads no files.
"""

SHIPPED = {
    "evidence_bias": -5.2756687293382,
    "evidence_weights": {
        "pairs": 0.3730339693162702,
        "rejected_share": -1.422464540683189,
        "residual": -3.3320601915389005,
        "fitness": 3.5635294511489186,
        "support": -0.21865253599505372,
        "conflict_share": -2.9542400727510385,
    },
    "confidence_bias": -0.8008385294790415,
    "confidence_evidence": 0.3147052281786048,
    "confidence_rival": 0.0,
    "confidence_gap": 1.6001051856612856,
    "ranking_bias": -5.583851154420792,
    "ranking_weights": {
        "pairs": 0.6613410232931233,
        "rejected_share": -1.3639612631258466,
        "residual": -0.06023088178297997,
        "fitness": 3.576389492913578,
        "support": -0.16579065724469286,
        "conflict_share": -2.5764304620478486,
    },
    "min_confidence": 0.7272806499763466,
    "fitted_by": "benchmarks/calibrate_confidence.py --sequences 3 --starts 4 --holdout-sequences "
    "2 --write --figure docs/img/reliability.png",
    "data": "protocol attempts of seed 1 (3 sequences, 4 starts), views of buildings [100, 101, "
    "102, 103, 104, 105] (6 per variant and size), observations of buildings [10, 11, 12, "
    "13, 14, 15] (10 per size); kinds cad, dynamic, layout-clean, layout-dynamic, "
    "layout-noisy, observed, reconstruction; 1008 answers, 8594 hypotheses",
}
