"""The shipped confidence model's coefficients (see `semloc.decision.ConfidenceModel`).

Written by `benchmarks/calibrate_confidence.py --write`; data, not I/O: the core reads no files.
"""

SHIPPED = {
    "evidence_bias": -5.2765101659708264,
    "evidence_weights": {
        "n_pairs": 0.37295305325728206,
        "rejected_share": -1.4234049022916215,
        "residual": -3.3320379089120675,
        "fitness": 3.564411085154988,
        "n_support": -0.21759803693132487,
        "conflict_share": -2.95333044354862,
    },
    "confidence_bias": -0.9059459588805732,
    "confidence_evidence": 0.26835504008035166,
    "confidence_rival": -0.11424340282237558,
    "confidence_gap": 2.2397793120114975,
    "ranking_bias": -5.561483183480298,
    "ranking_weights": {
        "n_pairs": 0.661672824486766,
        "rejected_share": -1.3638612935690333,
        "residual": -0.09819050035223457,
        "fitness": 3.5512003363244395,
        "n_support": -0.1658809568671077,
        "conflict_share": -2.580520296410085,
    },
    "min_confidence": 0.8389101439863255,
    "fitted_by": "benchmarks/calibrate_confidence.py --sequences 3 --starts 4 --holdout-sequences "
    "2 --write --figure docs/img/reliability.png",
    "data": "protocol attempts of seed 1 (3 sequences, 4 starts), views of buildings [100, 101, "
    "102, 103, 104, 105] (6 per variant and size), observations of buildings [10, 11, 12, "
    "13, 14, 15] (10 per size); kinds cad, dynamic, layout-clean, layout-dynamic, "
    "layout-noisy, observed, reconstruction; 1008 answers, 8595 hypotheses",
}
