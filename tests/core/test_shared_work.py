"""Work an update shares or skips gives the answers the full computation gives: the negative
evidence of several looks under one pose (`semloc.coverage.Accounting`), asked again for the
answer's support within an update, on a hard walk and after a `Localizer.state()` round trip."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from semloc import Localizer, LocalizerConfig
from semloc.coverage import Accounting, Looks, expected_unseen
from semloc.sightings import Sightings
from semloc.sim.layouts import layout
from semloc.sim.longwalk import LongWalk, WalkConfig, World, tiled


def _accounted_alone(pose, global_positions, local, allowance, move_m) -> np.ndarray:
    """The accounting rule measured afresh for one window (as it was before it was shared)."""
    accounted = np.zeros(len(global_positions), dtype=bool)
    R, t = pose[:3, :3], pose[:3, 3]
    farther = []
    for position, candidates in local:
        if not len(candidates):
            continue
        gaps = np.linalg.norm(global_positions[candidates] - (R @ position + t), axis=1)
        nearest = int(np.argmin(gaps))
        if gaps[nearest] <= allowance[candidates[nearest]]:
            accounted[candidates[nearest]] = True
        else:
            farther.append((gaps, candidates))
    for gaps, candidates in farther:
        free = [i for i in np.argsort(gaps) if gaps[i] <= move_m and not accounted[candidates[i]]]
        if free:
            accounted[candidates[free[0]]] = True
    return accounted


@pytest.mark.parametrize("seed", range(5))
def test_one_accounting_for_the_windows_of_several_looks_equals_each_measured_alone(seed):
    rng = np.random.default_rng(seed)
    positions = rng.uniform(0, 6, (40, 3))
    allowance = rng.uniform(0.2, 0.8, 40)
    pose = np.eye(4)
    pose[:3, 3] = rng.normal(0, 0.3, 3)
    local = [
        (positions[rng.integers(40)] + rng.normal(0, 1.0, 3), np.sort(rng.choice(40, k, False)))
        for k in rng.integers(0, 6, 25)
    ]
    shared = Accounting(pose, positions, allowance, 1.5)
    for start in (0, 5, 12, 20, 24):  # the windows since older and newer looks
        window = list(enumerate(local))[start:]
        alone = _accounted_alone(pose, positions, [x for _, x in window], allowance, 1.5)
        assert shared.accounted(window).tolist() == alone.tolist()


def _unseen_look_by_look(self, pose, looks=None):
    """`Sightings.unseen` as computed before its work was shared: each look alone."""
    if looks is None:
        looks = [(self.window.updates, self.look)]
    context = self.context
    settings = Looks(move_m=context.config.tracking.move_m)
    expected, unseen = set(), set()
    for update, look in looks:
        origin = pose[:3, :3] @ look.origin + pose[:3, 3]
        near = np.array(context.tree.query_ball_point(origin, look.range_m + 0.5), dtype=int)
        local = [(self.found[i][0].position, self.found[i][1]) for i in self.window.since(update)]
        seen, absent = expected_unseen(
            pose, [look], context.map.positions, context.diagonals, local,
            context.allowances, settings, near,
        )  # fmt: skip
        expected.update(seen.tolist())
        unseen.update(absent.tolist())
    return np.array(sorted(expected), dtype=int), np.array(sorted(unseen), dtype=int)


def _answer(result) -> tuple:
    support = result.support
    return (
        result.status,
        result.reason,
        None if result.pose is None else np.asarray(result.pose).tolist(),
        [(h.pairs, h.n_missing, h.n_expected) for h in result.hypotheses],
        None if support is None else (support.n_missing, support.n_expected, support.missing_ids),
    )


def test_a_hard_walk_with_coverage_answers_as_with_each_look_weighed_alone(monkeypatch):
    """The shared and asked-again negative evidence gives every answer of a hard walk (an old
    map, mislabels, phantoms, kidnaps) as computed look by look, also after a round trip of
    both Localizers through `state()`."""
    global_map = tiled(layout(40, seed=3, points_per_object=60), 3, 1, keep=0.7, seed=3)
    world = World(moved=0.2, gone=0.1, phantoms=0.3, split=0.05, merged=0.05)
    config = WalkConfig(keyframes=80, kidnap_at=30, lookalike_at=55, world=world,
                        wrong_label_rate=0.1, points_per_object=60)  # fmt: skip
    walk = list(LongWalk(global_map, replace(config, redetections=config.max_visible), seed=3))
    fast, full = (Localizer(global_map, LocalizerConfig(), local_up=[0, 0, 1]) for _ in range(2))
    statuses = set()
    for k, frame in enumerate(walk):
        if k == 40:
            fast, full = (
                Localizer.restore(global_map, loc.state(), loc.window.objects, local_up=[0, 0, 1])
                for loc in (fast, full)
            )
        answer = fast.update(frame.objects, position=frame.T_odom_robot, coverage=frame.coverage)
        with monkeypatch.context() as patch:
            patch.setattr(Sightings, "unseen", _unseen_look_by_look)
            reference = full.update(
                frame.objects, position=frame.T_odom_robot, coverage=frame.coverage
            )
        assert _answer(answer) == _answer(reference)
        statuses.add(answer.status)
    assert {"localized", "ambiguous"} <= statuses
