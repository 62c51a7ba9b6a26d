"""The result and its details print what a user looks at first, with the getters' values."""

from __future__ import annotations

import re

import lidarcal
from lidarcal import sim


def _number(text: str, name: str) -> float:
    match = re.search(rf"{name}=([-\d.]+)", text)
    assert match, (name, text)
    return float(match.group(1))


def test_targetless_details_repr() -> None:
    scene = sim.street_scene(seed=0, side="left")
    result = lidarcal.calibrate_targetless(scene.reference, scene.target)
    details = result.details
    text = repr(details)
    assert text.startswith("TargetlessDetails(")
    assert _number(text, "matched_planes") == len(details.planes_reference)
    assert _number(text, "verified") == details.verified
    assert abs(_number(text, "best_score") - details.best_score) < 5e-4
    assert abs(_number(text, "agreement") - details.agreement) < 5e-4
    assert f"ambiguous={details.ambiguous}" in text


def test_planar_details_repr() -> None:
    scene = sim.corner_scene(seed=0)
    details = lidarcal.calibrate_planes(scene.reference, scene.target, up=[0, 0, 1]).details
    text = repr(details)
    assert text.startswith("PlanarDetails(matched_planes=3,")
    assert _number(text, "ordering_chosen") == details.ordering["chosen"]
    assert f"used_up={details.ordering['used_up']}" in text


def test_pole_details_repr() -> None:
    scene = sim.poles_scene(seed=0)
    details = lidarcal.calibrate_poles(scene.reference, scene.target).details
    text = repr(details)
    assert text.startswith("PoleDetails(")
    assert _number(text, "matched_poles") == len(details.poles_reference)
    assert _number(text, "hypotheses") == len(details.hypotheses)
    assert _number(text, "chosen") == details.chosen
