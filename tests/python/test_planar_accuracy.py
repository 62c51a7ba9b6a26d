"""The planar method against ground truth: the seed's protocol and simulated VLP-16 corners."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "benches"))
import planar_accuracy


def test_seed_protocol_beats_the_paper() -> None:
    rows = planar_accuracy.paper_protocol(trials=10)
    assert len(rows) == 14  # no failure: every cell has its 10 trials
    mean_rot = np.mean([r["rotation"] for r in rows])
    mean_trans = np.mean([r["translation"] for r in rows])
    assert mean_rot <= 0.0015, mean_rot  # the paper: 0.0045 rad
    assert mean_trans <= 0.007, mean_trans  # the paper: 0.011 m
    for r in rows:
        assert r["rotation"] <= max(r["paper_rotation"], 0.002), r
        assert r["translation"] <= max(r["paper_translation"], 0.008), r


def test_vlp16_corners_within_5_mrad_and_3_cm() -> None:
    for name, errs in planar_accuracy.corner_scenes(runs=10).items():
        assert len(errs) == 10
        for rot, trans in errs:
            assert rot < 5e-3 and trans < 0.03, (name, rot, trans)
