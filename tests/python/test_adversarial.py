"""lidarcal.scenarios and calibration trust on a sample of its adversarial scenes.

The full count is ``python benches/adversarial.py``; here a few scenes per family must not get a
wrong answer from any method (a refusal is fine, a wrong transform is not).
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial import cKDTree

import lidarcal
from lidarcal import scenarios

ROT_TOL = 0.05  # rad
TRANS_TOL = 0.10  # m

#: Two scenes per family, picked among those the first benchmark run (lidarcal 0.1.0) got wrong,
#: one per failure it showed: corner 59 a kerb-high pavement taken for the ground by one sensor
#: (planes), corner 87 a plain corner turned 180 deg (targetless); poles 1 a bright untaped
#: facade taken for tape, poles 9 the translation along two nearly parallel poles; partial 4 a
#: slide along the street, partial 66 a street "corner" 90 deg off (auto keeping planes); corridor
#: 86 a room with a door turned 180 deg, corridor 29 a furnished room 0.5 m off; repeated 29
#: identical boxes turned 180 deg, repeated 182 a colonnade shifted by one column.
#: Added after the second round: corner 191 a corner 1.5 deg / 11 cm off (planes, refused by the
#: agreement gain), partial 12 sensors 7.8 m apart, beyond max_translation (targetless returned a
#: quarter turn within 5 m; refused as out of range since the challengers).
#: Added after the third round: partial 139, a street turned 180 deg whose two best hypotheses were
#: one flip 0.4 m apart, with the truth (beyond max_translation) third (refused as ambiguous since
#: the next contender is polished too); corridor 86 is refused the same way; repeated 25, two
#: identical boxes swapped whose scores (0.086 and 0.077) differ by less than their sampling error;
#: corner 96, a 16-beam corner whose winning start settled 23 cm too high (a start 0.2 m away,
#: merged with it by the ranking, settles on the truth and keeps free space clear); corner 193,
#: whose exact plane-refined pose the final ICP pulled 18 cm along the weakest direction.
#: Added after the fourth round: corner 53 and 62, a pavement 15 and 11 cm high taken for the
#: ground by one sensor (planes: refused since each plane's inliers must land next to its
#: partner's); corridor 170 and 81, a corridor turned upside down about its axis (the same box;
#: the 32-beam reference saw more of the turned 16-beam scan than of the upright one), refused as
#: ambiguous since the best pose is also probed turned half a turn about the planes' axes.
#: Added after the fifth round: corridor 1086 (a held-out seed), a dead-end corridor turned upside
#: down whose only rivals were its own slides along the corridor; it must stay refused now that a
#: rival the check rules out is dismissed (slides of the best pose are not); corridor 1092 (held
#: out), a room returned 180 degrees off until the half turns went through its middle too.
#: Added after the sixth round: repeated 182, a colonnade returned one column off (it overlaps
#: more there than at the truth, so the verification ranked it first): refused as ambiguous since
#: the best pose's own slides to other peaks along the colonnade are probed and one keeps the free
#: space clearly clearer.
#: Added after the eighth round: corridor 1087 (held out), a bare room returned 180 degrees off:
#: the target saw more of the turned room (60 % overlap against the truth's 36 %), so the
#: truth scored too low to count as a rival; refused since a half turn the check cannot tell
#: from the best pose (as close an agreement both ways, free space as clear) is a twin.
#: Added after the ninth round, from the second fresh set (seeds 3000-3499): partial 3057, a
#: street returned 1.03 m off along its weakly held direction, which the check passed because its
#: re-alignment stopped after 33 cm (it is now run again while it keeps moving); repeated 3082, a
#: colonnade returned one period (4 m) off, whose slide to the truth the check could not tell
#: from it (a slide like that makes the result ambiguous now).
#: Added after the twelfth round, from the fresh set 7000-7999: corner 7113, a corner 12 cm off
#: (planes) because a kerb 18 cm above the road lay in the band whose noise set the target's
#: inlier threshold (22 cm); repeated 7116 and 7127, boxes returned turned 90 and 176 degrees by
#: a best pose explaining 11.8 % and 4.2 % of the target (targetless, and auto through it).
#: Added from the fresh set 9000-9999: corner 9066, a square corner seen by a sensor on its side,
#: returned turned 120 degrees and 2.5 m off (targetless, and auto through it): refused as
#: ambiguous since the best pose is also probed turned a third of a turn about the corner's
#: diagonals, and the truth among those turns keeps the free space clearer. Corners 9053, 9073 and
#: 8135 and street 8102, returned 11-32 cm off by targetless along weakly held directions:
#: refused since the check's re-alignment moves them 11-33 cm (a counted move over 10 cm).
#: Corner 7134, returned 1.38 m off by the corner method (a box top 1.4 m up taken for the
#: ground by the target), and room 8143, returned 7 m off by it (one cloud's third plane from
#: another wall): their first results put 15.8 % and 4.5 % of the points into free space, so
#: each role is tried with the next parallel planes; 8143 is solved that way, 7134 refused
#: since its best alternative (the ground matched to a pavement 12 cm up) is moved 7 cm by the
#: check's re-alignment. Corner 11070 (fresh set 11000-11999), returned turned 120 degrees by
#: targetless: its third largest reference plane lay parallel to the second, so no square corner
#: was seen and no third turn probed; the largest planes of three directions are taken now.
#: Poles 11189 (fresh set 11000-11999), returned 1.03 m off by targetless, and by auto through
#: it: the truth lay 1.09 m along the best pose's free direction, at the third peak of its slide
#: score, and kept the free space clearer (0.8 % of the points against 3.4 %); clearer slides
#: are sought among four peaks now, so it is refused as ambiguous. Poles 10166 (fresh set
#: 10000-10999), returned 10.4 cm off by the pole method with a clean check whose re-alignment
#: moved it 10.5 cm: a pole pose moved over 10 cm is settled like one the check refuses (here:
#: refused, and auto keeps the targetless result, 1.1 cm off).
#: Rooms returned turned half a turn by the corner method, its two clouds having taken different
#: corners of the room: 12006 and 12104 (fresh set 12000-12999) with 0 % and 2.6 % of the points
#: in free space, so no next plane was tried, and 12046 and 11138 with 15.7 % and 18.8 %, whose
#: alternatives left the correspondence tied (a room's corners are nearly square), and 10180 with
#: 8.7 %. A cloud with a
#: large sheet facing a plane of its corner across the sensor now has its next planes tried, each
#: shift of a tie in turn; 12006 and 12104 are refused as ambiguous (another corner of the room
#: fits as well), 12046, 11138 and 10180 since an enclosed scene keeps a right pose's free space
#: clear.
#: Corner 13055 (fresh set 13000-13999), returned 27 cm off and 1.3 degrees tilted by targetless:
#: the ground matched a pavement 18 cm up, a local optimum with 13.1 % of the points in free
#: space that the check's re-alignment does not leave. The best pose is now also restarted a
#: few decimetres along the largest plane's normal; 0.4 m up it settles on the truth (0.3 %),
#: and the result is refused as ambiguous.
#: Corner 13057 (the same set), returned 77 degrees off by the corner method: its target took a
#: container's side for a wall 28 degrees from it, and the next planes of a role were sought only
#: within 10 degrees of parallel; within 30 degrees the missed wall is tried, and it is solved.
#: Corner 14106 (fresh set 14000-14999), returned 3.3 m along a wall by targetless: the truth, a
#: verified contender, agreed 98 % / 98 % on its overlap against 82 % / 85 %, both with no point
#: in free space; a clearly better contender now counts when the free space is clear both ways.
#: From the fresh sets 14000-16999: poles 16022 and 14004, returned 13-14 cm off and 0.95-1.4
#: degrees tilted by the pole method (the scene's re-alignment settled the tilted pose where it
#: was, 14-15 % of the points in free space for 16022): a second start with the ground's tilt and
#: height settles on the truth. Corner 16024, returned 42 cm low by targetless (a small ground
#: patch, the largest plane a wall), and poles 14072, 1.3 m off: restarted along their weakest
#: direction they settle clearer of free space, and they are refused as ambiguous.
#: Corner 18004 (fresh set 18000-18999), returned turned 105 degrees by targetless onto the other
#: of two similar corners, which overlaps more: the truth, a verified contender, agrees 7 and 2.8
#: points better and keeps the free space clear (2.7 % at the wrong pose); a contender clearer of
#: free space now counts from 2 points better both ways.
#: Repeated 21050 (fresh set 21000-21999), two identical boxes returned turned 90 degrees and
#: 1.9 m off by targetless: the truth, a verified contender, agrees 8 and 19 points better with a
#: point more in free space (2.1 % against 1.5 %); a contender 6 points better both ways now
#: counts while it puts at most a point more there.
#: Corner 21188 (the same set), a corner square within 3 degrees seen by a sensor on its side,
#: returned turned 120 degrees and 4.5 m off by targetless with no point in free space: third
#: turns of a square corner are now probed whatever the free space, and one that fits as well
#: makes the result ambiguous (auto returns the corner method's exact result). Repeated 21027
#: and 21417 (fresh set 21000-21439), colonnades returned one period (3.9 and 3.0 m) off by
#: targetless and auto through it: a result that the reference's own period shifts onto a pose
#: fitting as well is now refused as ambiguous. Repeated 22082 and 22145 (fresh set 22000-22199),
#: rows of boxes before a long wall returned one period (4.0 and 5.8 m) off by targetless and auto
#: through it: the wall, most of the structure and landing on itself at any shift along it, hid
#: the period; it is now sought among the structure that does not land on itself at half the
#: shift. Corridor 22066 (the same set), pilasters every 4.6 m, returned turned 180 degrees: the
#: same period finds its twin. Poles 22091 (the same set), returned 1.04 m off from the ground
#: sweep at a verification score of 0.021, the truth verified at -0.004: within one standard error
#: of the two scores once the free-space violations' noise counts, and fitting as well, it is a
#: rival. Repeated 12056 (fresh set 12000-12999), a row of boxes returned one period (3.3 m) off:
#: its runner-up now ties. Corridor 23152 (fresh set 23000-23199), pilasters every 5.1 m,
#: returned turned 180 degrees and 0.9 m off from the ground sweep by targetless and auto: its
#: runner-up (the truth, scoring 95 % of it) was ruled out as unverifiable along the vertical,
#: where the best pose itself holds only 1.4 % of its translation information; such a runner-up
#: that fits as well and keeps the free space clearer (none against 4.3 %) is now a rival.
#: Corner 23000 (the same set), a corner seen by a unit on its side, returned 4.47 m along a wall
#: by targetless and auto: a contender 6.2 m from it, unverifiable along the vertical as the
#: truth is, agrees 100 % / 97 % against 78 % / 83 % with no point in free space, and the result
#: holds only 3.1 % of its translation information along its weakest direction.
#: Corner 24150 (fresh set 24000-24199), returned turned 89 degrees and 2.7 m off by targetless
#: and auto: the truth, the tenth distinct contender at 46 % of the best score, passes the check
#: where its re-alignment settles it and agrees 97 % / 94 % against the result's 76 % / 71 %,
#: with no point in free space either way; such a turned contender now counts down to 40 % of the
#: score.

SAMPLE = [
    ("corner", 59),
    ("corner", 87),
    ("poles", 1),
    ("poles", 9),
    ("partial", 4),
    ("partial", 66),
    ("corner", 191),
    ("partial", 12),
    ("corridor", 86),
    ("partial", 139),
    ("repeated", 25),
    ("corner", 96),
    ("corner", 193),
    ("corridor", 29),
    ("repeated", 29),
    ("corner", 53),
    ("corner", 62),
    ("corridor", 170),
    ("corridor", 81),
    ("corridor", 1086),
    ("corridor", 1092),
    ("repeated", 182),
    ("corridor", 1087),
    ("partial", 3057),
    ("repeated", 3082),
    ("corner", 7113),
    ("repeated", 7116),
    ("repeated", 7127),
    ("corner", 9066),
    ("corner", 9053),
    ("corner", 9073),
    ("corner", 8135),
    ("partial", 8102),
    ("corner", 7134),
    ("corridor", 8143),
    ("corner", 11070),
    ("poles", 11189),
    ("poles", 10166),
    ("corridor", 12006),
    ("corridor", 12104),
    ("corridor", 12046),
    ("corridor", 11138),
    ("corridor", 10180),
    ("corner", 13055),
    ("corner", 13057),
    ("corner", 14106),
    ("poles", 16022),
    ("poles", 14004),
    ("corner", 16024),
    ("poles", 14072),
    ("corner", 18004),
    ("repeated", 21050),
    ("corner", 21188),
    ("repeated", 21027),
    ("repeated", 21417),
    ("repeated", 22082),
    ("repeated", 22145),
    ("corridor", 22066),
    ("poles", 22091),
    ("repeated", 12056),
    ("corridor", 23152),
    ("corner", 23000),
    ("corner", 24150),
]


def _errors(truth: np.ndarray, est: np.ndarray) -> tuple[float, float]:
    r = truth[:3, :3].T @ est[:3, :3]
    rot = float(np.arccos(np.clip((np.trace(r) - 1.0) / 2.0, -1.0, 1.0)))
    return rot, float(np.linalg.norm((np.linalg.inv(truth) @ est)[:3, 3]))


@pytest.mark.parametrize(("family", "seed"), SAMPLE)
def test_no_wrong_answer(family: str, seed: int) -> None:
    scene = scenarios.make(family, seed)
    wrong = []
    for method in scene.methods:
        try:
            result = lidarcal.calibrate(scene.reference, scene.target, method=method)
        except (lidarcal.CalibrationError, ValueError):
            continue  # refusing is allowed
        rot, trans = _errors(scene.reference_from_target, np.asarray(result.transform))
        if not (rot <= ROT_TOL and trans <= TRANS_TOL):
            wrong.append(
                f"{method} (by {result.method}): {np.degrees(rot):.2f} deg, {100 * trans:.1f} cm"
            )
    assert not wrong, (
        f"scenarios.make({family!r}, {seed}) got wrong answers: {'; '.join(wrong)}\n"
        f"{scene.description}"
    )


#: Solvable scenes that a method must solve, not only not get wrong, each once refused by it:
#: targetless corner 36 and 46, whose runner-up (a half turn) the check rules out as unverifiable
#: or inconsistent while it passes the best pose; pole scenes 44 and 142, whose pole-only pose sat
#: 5 cm low and 0.1-0.7 deg tilted until the scene settled it; held-out corner 1017, returned 27 cm
#: low (box tops taken for the ground) until a re-alignment into free space stopped counting;
#: repeated 63 (two identical boxes), refused as ambiguous over a slide 0.3 m off that the check's
#: re-alignment carries back onto the best pose; corner 98, refused as ambiguous over a slide
#: 0.44 m off that the check passes but that puts 8.6 % of the points into free space (the best
#: pose none); poles 170, whose half turn the check passes but which agrees 3-6 points less
#: than the best pose on its overlap, so it is no twin; poles 117, whose half turn failed the check
#: only by its re-alignment and is judged where that re-alignment settles it (unverifiable
#: there, so ruled out); corner 5, whose slide along its free direction agrees as closely but puts
#: 18.3 % of the points into free space against the best pose's 9.8 %, so it is no twin of it.
#: Corner 7113 (planes), 12 cm off until the noise band was refitted by RANSAC; corner 76, the
#: correct result that explains the least of its target (14.3 %), above the agreement floor.
#: Corner 8135 (auto), refused as inconsistent methods while targetless returned it 32 cm off; the
#: corner method's exact result stands once that targetless result is refused. Room 8143
#: (planes), returned 7 m off until a role was tried with the next parallel plane. Corridor 2012
#: (a fresh seed of the eighth round), a room the corner method matched to its mirror image and
#: returned turned 180 degrees, 8 m off (31 % overlap, 4 % of the points in free space; auto
#: refused it as inconsistent with targetless): the next plane finds the truth (94 %, none).
#: Poles 11189 (auto), which returned the targetless method's pose 1.03 m off over the pole
#: method's correct one until that pose was refused as ambiguous. Corner 13057 (planes), returned
#: 77 degrees off until the next planes of a role were sought within 30 degrees of it.
#: Corners 188 and 14184 (targetless), refused as ambiguous over a restart along
#: the largest plane's normal that kept the free space clearer than the best verified pose, until
#: the restart was weighed against the final pose (0.0-3.8 % of the points in free space, none
#: once shifted by the check's resolution). Corner 21188 (auto): the corner method's exact
#: result once the targetless one is refused over a square corner's third turn. Repeated 12087
#: (targetless): a colonnade whose odd box both sensors see; shifted by the period, the result
#: agrees clearly less, so it is no twin of itself. (Repeated 10109, a colonnade with a wall
#: behind it, is refused since that change: the shift agrees 81 % / 83 % against 83 % / 84 %.)
#: Repeated 12015, 12165 and 22197 (targetless): a pose verifying within the noise of the best
#: one's score but agreeing 8-26 points less, or putting 7 % more of the points into free
#: space, is no rival. (Poles 12032, here since the restart was weighed against the final pose,
#: is refused since scores tie within their noise: a pose 0.73 m away verifies within it and the
#: check prefers it, 69 % / 55 % against 58 % / 40 %, 0.8 % of the points in free space against
#: 2.5 %.)
#: Corridors 23165 and 23171 (targetless), whose half turns are unverifiable along the vertical
#: that the result barely holds and fit as well, but put 0.5-1.5 % of the points into free space
#: against none: no rival. Corners 12007 and 12128 (targetless), whose unverifiable contenders
#: 2-3 m away agree clearly better than the result (94-98 % against 66-82 %), while the result
#: holds 13-19 % of its translation information along its weakest direction; corners 22035 and
#: 23179 (targetless), whose unverifiable contenders that agree clearly better lie beyond
#: max_translation: none of them is a rival.
#: Corner 52 (planes, and auto through it): a corner whose plane orderings tie, refused until the
#: check judged each tied ordering; one alone passes, overlapping 73 % of the scene.
#: Corner 40193 (auto): the targetless method is refused (a turned contender fits clearly
#: better, see REFUSED) and the corner method's exact result stands.
#: Corner 100014 (planes): one cloud takes a pavement 17 cm high for the ground; the result, 15 cm
#: off, puts 1.9 % of the points into free space, which starts the next-plane search since the
#: trigger went from 3 to 1.5 %, and the pavement's swap solves it exactly.
#: Corners 100049 and 100088 (auto): the corner method's exact result and a targetless one 34 and
#: 42 cm off both pass the check with certificates under 0.1 apart; the corner result keeps the
#: free space clear (0 and 0.3 %) where the targetless one puts 5.0 and 1.9 %, and stands.
#: Poles 110063 (auto): the pole method's correct result puts 2.9 % of the points into free space,
#: a targetless pose 94 cm off 0.6 %, and `auto` refused the two as inconsistent methods; since
#: the final ICP fits scan lines by their planes' normals the targetless pose is exact too.
MUST_SOLVE = [
    ("poles", 117, "targetless"),
    ("corner", 5, "targetless"),
    ("repeated", 63, "targetless"),
    ("corner", 98, "targetless"),
    ("poles", 170, "targetless"),
    ("corner", 1017, "targetless"),
    ("corner", 36, "targetless"),
    ("corner", 46, "targetless"),
    ("poles", 44, "poles"),
    ("poles", 142, "poles"),
    ("corner", 7113, "planes"),
    ("corner", 76, "targetless"),
    ("corner", 8135, "auto"),
    ("corridor", 8143, "planes"),
    ("corridor", 2012, "planes"),
    ("corridor", 2012, "auto"),
    ("poles", 11189, "auto"),
    ("corner", 13057, "planes"),
    ("corner", 188, "targetless"),
    ("corner", 14184, "targetless"),
    ("corner", 14042, "planes"),
    ("corner", 18192, "planes"),
    ("corridor", 20060, "planes"),
    ("corner", 21188, "auto"),
    ("repeated", 12087, "targetless"),
    ("repeated", 12015, "targetless"),
    ("repeated", 12165, "targetless"),
    ("repeated", 22197, "targetless"),
    ("corridor", 23165, "targetless"),
    ("corridor", 23171, "targetless"),
    ("corner", 12007, "targetless"),
    ("corner", 12128, "targetless"),
    ("corner", 22035, "targetless"),
    ("corner", 23179, "targetless"),
    ("corner", 52, "planes"),
    ("corner", 52, "auto"),
    ("corner", 40193, "auto"),
    ("corner", 100014, "planes"),
    ("corner", 100049, "auto"),
    ("corner", 100088, "auto"),
    ("poles", 110063, "auto"),
]


@pytest.mark.parametrize(("family", "seed", "method"), MUST_SOLVE)
def test_solvable_scene_is_solved(family: str, seed: int, method: str) -> None:
    scene = scenarios.make(family, seed)
    assert scene.solvable is True
    result = lidarcal.calibrate(scene.reference, scene.target, method=method)
    rot, trans = _errors(scene.reference_from_target, np.asarray(result.transform))
    assert rot <= ROT_TOL and trans <= TRANS_TOL, (np.degrees(rot), trans)
    assert result.check.verdict == "consistent"


def test_auto_keeps_a_far_result_the_targetless_best_pose_confirms() -> None:
    # The sensors are 6.5 m apart, beyond the targetless method's max_translation (5 m): it is
    # refused as out of range, but its best pose without the bound is the corner method's, so
    # auto keeps that (partial 80162, where the two differ, is refused in REFUSED).
    scene = scenarios.make("partial", 60135)
    assert np.linalg.norm(scene.reference_from_target[:3, 3]) > 5.0
    result = lidarcal.calibrate(scene.reference, scene.target, method="auto")
    assert result.method == "planes"
    rot, trans = _errors(scene.reference_from_target, np.asarray(result.transform))
    assert rot <= ROT_TOL and trans <= TRANS_TOL, (np.degrees(rot), trans)


def test_check_does_not_follow_a_realignment_into_free_space() -> None:
    # The true pose of this 16-beam corner: point-to-plane re-alignment pulls it 28 cm down onto
    # box tops, where 4 % of the points land in space the other sensor saw through (none here).
    scene = scenarios.make("corner", 1017)
    report = lidarcal.check(scene.reference, scene.target, scene.reference_from_target)
    assert report.verdict == "consistent", report.reason
    assert "free space" in report.reason
    assert report.correction_translation_m > 0.2
    # A pose 1 degree off is still flagged: its re-alignment comes back toward the truth.
    turned = scene.reference_from_target.copy()
    c, s = np.cos(np.radians(1.0)), np.sin(np.radians(1.0))
    turned[:3, :3] = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]]) @ turned[:3, :3]
    assert lidarcal.check(scene.reference, scene.target, turned).verdict != "consistent"


def test_check_follows_a_realignment_that_keeps_moving() -> None:
    # A street whose overlap holds one direction weakly: the pose the targetless method once
    # returned here, the truth moved about 1 m in the target's frame, passed a check that judged
    # only the re-alignment's first run (it moved the pose 32 cm and stopped, under the 50 cm
    # tolerance of weakly held directions). Run again while it keeps moving, it comes back 94 cm.
    scene = scenarios.make("partial", 3057)
    moved = np.eye(4)
    moved[:3, 3] = [0.37, 0.05, -0.97]
    report = lidarcal.check(scene.reference, scene.target, scene.reference_from_target @ moved)
    assert report.verdict == "inconsistent", report.reason
    assert report.correction_translation_m > 0.5, report


def test_make_is_deterministic() -> None:
    for family in scenarios.FAMILIES:
        a, b = scenarios.make(family, 3), scenarios.make(family, 3)
        assert np.array_equal(a.reference, b.reference)
        assert np.array_equal(a.target, b.target)
        assert np.array_equal(a.reference_from_target, b.reference_from_target)
        assert (a.solvable, a.description, a.methods) == (b.solvable, b.description, b.methods)
        assert not np.array_equal(a.target, scenarios.make(family, 4).target)


def test_unknown_family_and_bad_seed_raise() -> None:
    with pytest.raises(ValueError, match="unknown family"):
        scenarios.make("volcano", 0)
    with pytest.raises(ValueError):
        scenarios.make("corner", -1)


@pytest.mark.parametrize("family", scenarios.FAMILIES)
def test_scenario_shapes_and_truth(family: str) -> None:
    scene = scenarios.make(family, 5)
    assert scene.family == family and scene.seed == 5
    for cloud in (scene.reference, scene.target):
        assert cloud.ndim == 2 and cloud.shape[1] == 4 and cloud.dtype == np.float64
        assert cloud.shape[0] > 1000
        assert np.all(np.isfinite(cloud))
        assert np.all((cloud[:, 3] >= 0) & (cloud[:, 3] <= 255)) and np.ptp(cloud[:, 3]) > 0
    t = scene.reference_from_target
    assert t.shape == (4, 4)
    assert np.allclose(t[3], [0, 0, 0, 1])
    assert np.allclose(t[:3, :3].T @ t[:3, :3], np.eye(3), atol=1e-9)
    assert np.isclose(np.linalg.det(t[:3, :3]), 1.0)
    assert scene.solvable in (True, False, None)
    assert "auto" in scene.methods and "targetless" in scene.methods
    assert set(scene.methods) <= {"auto", "planes", "targetless", "poles"}
    assert scene.description.startswith(f"{family} 5:")
    # The truth maps the target scan onto the reference scan, a shifted one less well.
    tree = cKDTree(scene.reference[:, :3])

    def overlap(pose: np.ndarray) -> float:
        mapped = scene.target[:, :3] @ pose[:3, :3].T + pose[:3, 3]
        return float(np.mean(tree.query(mapped, distance_upper_bound=0.25)[0] < 0.25))

    off = t.copy()
    off[:3, 3] += 0.5  # half a metre along each axis: off the ground, off the walls
    assert overlap(t) > 0.05 and overlap(t) > overlap(off)


def test_degrade_is_deterministic_and_keeps_the_truth() -> None:
    scene = scenarios.make("corner", 3)
    assert scenarios.degrade(scene, "none") is scene
    for condition in scenarios.CONDITIONS[1:]:
        a, b = scenarios.degrade(scene, condition), scenarios.degrade(scene, condition)
        assert np.array_equal(a.reference, b.reference) and np.array_equal(a.target, b.target)
        assert np.array_equal(a.reference_from_target, scene.reference_from_target)
        assert a.description == f"{scene.description}; condition {condition}"
        assert a.methods == scene.methods and (a.family, a.seed) == (scene.family, scene.seed)
        for cloud in (a.reference, a.target):
            assert cloud.ndim == 2 and cloud.shape[1] == 4 and np.all(np.isfinite(cloud))
    assert not np.array_equal(
        scenarios.degrade(scene, "sparse-target").target,
        scenarios.degrade(scenarios.make("corner", 4), "sparse-target").target,
    )


def _azimuth_span_deg(cloud: np.ndarray) -> float:
    """The widest horizontal angle between returns (360 less the largest empty sector)."""
    az = np.sort(np.degrees(np.arctan2(cloud[:, 1], cloud[:, 0])))
    gaps = np.diff(np.concatenate([az, [az[0] + 360.0]]))
    return float(360.0 - gaps.max())


def test_degrade_conditions_do_what_they_say() -> None:
    scene = scenarios.make("corner", 3)
    assert scene.solvable is True
    assert _azimuth_span_deg(scene.target[:, :3]) > 300.0
    narrow = scenarios.degrade(scene, "narrow-fov")
    for cut, full in ((narrow.reference, scene.reference), (narrow.target, scene.target)):
        assert _azimuth_span_deg(cut[:, :3]) <= 120.0
        assert 0 < len(cut) < len(full)
        # Returns are kept, not made: each is a row of the full scan.
        assert set(map(tuple, cut)) <= set(map(tuple, full))
    half = scenarios.degrade(scene, "half-fov-target")
    assert np.array_equal(half.reference, scene.reference)
    assert _azimuth_span_deg(half.target[:, :3]) <= 180.0
    sparse = scenarios.degrade(scene, "sparse-target")
    assert np.array_equal(sparse.reference, scene.reference)
    assert 0.2 < len(sparse.target) / len(scene.target) < 0.3
    noisy = scenarios.degrade(scene, "outliers")
    for more, full in ((noisy.reference, scene.reference), (noisy.target, scene.target)):
        known = set(map(tuple, full))
        extra = np.array([row for row in more if tuple(row) not in known])
        assert len(more) == len(full) + len(extra) and len(extra) == int(0.03 * len(full))
        ranges = np.linalg.norm(extra[:, :3], axis=1)
        assert np.all((ranges >= 1.0) & (ranges <= 15.0))
        assert np.all(extra[:, 3] < scenarios.TAPE_INTENSITY)  # never taken for tape
    # Only spurious returns keep a solvable scene solvable for sure; nothing makes an
    # unsolvable one solvable.
    assert (narrow.solvable, half.solvable, sparse.solvable, noisy.solvable) == (
        None,
        None,
        None,
        True,
    )
    unsolvable = next(
        s for s in (scenarios.make("corridor", i) for i in range(20)) if s.solvable is False
    )
    for condition in scenarios.CONDITIONS:
        assert scenarios.degrade(unsolvable, condition).solvable is False
    with pytest.raises(ValueError, match="unknown condition"):
        scenarios.degrade(scene, "fog")


def test_families_list_methods_they_can_use() -> None:
    assert scenarios.FAMILIES == ("corner", "poles", "partial", "corridor", "repeated")
    assert "planes" in scenarios.make("corner", 0).methods
    assert "poles" in scenarios.make("poles", 0).methods
    assert scenarios.make("partial", 0).solvable is None


#: Scenes refused with a kind and a phrase of the reason: repeated 182, a colonnade whose
#: best-ranked pose is one column (3.9 m) off and passes the local check, while its slide to the
#: next peak along the colonnade is the truth, which keeps free space clearer. Repeated 7127 and
#: 7116: the boxes' best poses explain 4.2 % and (from the ground sweep) 11.8 % of the target, under
#: the agreement floors of 10 and 15 %. Corner 21188: a square corner whose third turn fits as well.
#: Repeated 21027: a colonnade, the result shifted by its period fits as well; repeated 22082 the
#: same before a long wall. Poles 22091: a pose 0.95 m from the best verifies within the noise and
#: fits as well (the best, from the ground sweep, held 1.12 % of the translation information in its
#: weakest direction, which refused it first until the final ICP fitted scan lines by their planes'
#: normals). Corridor 23152: its half turn (the truth) is unverifiable along the vertical, which the
#: best pose barely holds either, and fits as well. Corner 23000: an unverifiable contender within
#: range fits clearly better than a weakly held result. Corner 24150: a contender turned 89 degrees
#: passes the check where it settles and fits clearly better. Corner 40193: the best pose lies on
#: the scene's second corner, 81 degrees from the truth (the sixth contender, which agrees better
#: both ways and keeps the free space clear where the best pose puts 17 % of the points); refused as
#: ambiguous over that contender until the final ICP fitted scan lines by their planes' normals, and
#: since then because the check's re-alignment carries the result 8 cm and 1.2 degrees away. The
#: corner method's tied orderings: in corridor 19099 the one ordering that passes the check is
#: turned 90 degrees and overlaps 28 % of the scene, in corner 24019 turned 120 degrees and agreeing
#: 31 % / 34 %; room 13001, whose passing ordering is a half turn, is enclosed, where the check does
#: not break ties. Corner 60098 (a target on its side, 130 degrees off) and poles 50073 (92 cm along
#: the ground): poses from the ground sweep holding 1.00 % and 1.14 % of the translation information
#: in their weakest direction, under the sweep's floor of 1.5 %. Corner 70108: the result, 1.5 m
#: along the long wall, puts 19 % of the target's points into free space; the truth, the second
#: contender, passes the check and puts none there, though it agrees less on a smaller overlap.
#: Partial 80162: `auto` had the corner method's pose 17 m out and turned 90 degrees, where the
#: targetless method, refused as out of range, found its best pose 7.1 m out (the truth). Room
#: 100169 (planes): half a turn and 6 m off, its three planes put 4.4 % of the points into free
#: space in an enclosed scene, over the 4 % bound (5 % until then). Corridor 130003 (targetless): a
#: room seen by two 16-beam units, the result half a turn off and held by a hair (0.53 % along its
#: weakest direction); its half turn, unverifiable, fits as well. Corridor 180157 (targetless): a
#: 16-beam target on its side in a furnished room; the result had the floor on a wall (a half turn
#: about the bisector of their normals), and that swap of the two planes settles on the truth, which
#: ties by score.
REFUSED = [
    ("corner", 21188, "targetless", "ambiguous", "the corner's three planes are square"),
    ("repeated", 21027, "targetless", "ambiguous", "the reference repeats itself every"),
    ("repeated", 22082, "targetless", "ambiguous", "the reference repeats itself every"),
    ("poles", 22091, "targetless", "ambiguous", "verify equally well within the verification's"),
    ("corridor", 23152, "targetless", "ambiguous", "verify almost equally well"),
    ("corner", 23000, "targetless", "ambiguous", "fits where the clouds overlap clearly better"),
    ("corner", 24150, "targetless", "ambiguous", "fits where the clouds overlap clearly better"),
    ("corner", 40193, "targetless", "no_agreement", "the scene prefers a pose"),
    ("repeated", 182, "targetless", "ambiguous", "may repeat itself"),
    ("repeated", 7127, "targetless", "no_agreement", "too little common structure"),
    ("repeated", 7116, "targetless", "no_agreement", "from the ground sweep"),
    ("corner", 60098, "targetless", "unobservable", "for a pose from the ground sweep"),
    ("poles", 50073, "targetless", "unobservable", "for a pose from the ground sweep"),
    ("corner", 70108, "targetless", "ambiguous", "keeps the free space clear (0.0 %"),
    (
        "partial",
        80162,
        "auto",
        "inconsistent_methods",
        "where the targetless method was refused as out of range",
    ),
    ("corridor", 19099, "planes", "ambiguous", "only one passes the check, but it overlaps 28 %"),
    ("corner", 24019, "planes", "ambiguous", "only one passes the check, but it overlaps"),
    ("corridor", 13001, "planes", "ambiguous", "two orderings fit the normals equally well"),
    ("corridor", 100169, "planes", "no_agreement", "the free space of a right pose is clear"),
    ("corridor", 130003, "targetless", "ambiguous", "the check cannot verify it"),
    ("corridor", 180157, "targetless", "ambiguous", "180.0 deg and 1.64 m apart verify almost"),
]


@pytest.mark.parametrize(("family", "seed", "method", "kind", "phrase"), REFUSED)
def test_refused_with_its_reason(
    family: str, seed: int, method: str, kind: str, phrase: str
) -> None:
    scene = scenarios.make(family, seed)
    with pytest.raises(lidarcal.CalibrationError) as refused:
        lidarcal.calibrate(scene.reference, scene.target, method=method)
    assert refused.value.kind == kind
    assert phrase in str(refused.value)
