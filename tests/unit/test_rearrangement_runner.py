"""Tests for the runner's jobs and its store of finished episodes (no simulation)."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from kinet_rl.rearrangement import runner
from kinet_rl.rearrangement.results import EpisodeResult
from kinet_rl.rearrangement.runner import Job, make_jobs, run_rearrangement
from kinet_rl.rearrangement.settings import RearrangementSettings
from kinet_rl.rearrangement.store import EpisodeStore


def test_jobs_share_seeds_across_methods_and_record_videos() -> None:
    settings = RearrangementSettings(episodes=3, videos=1, num_objects=(2,))
    jobs = make_jobs(settings, settings.conditions(generalization=False))
    assert len(jobs) == 3 * len(settings.methods)
    assert {j.condition.name for j in jobs} == {"comparison"}
    seeds = {m: [j.seed for j in jobs if j.method == m] for m in settings.methods}
    assert all(s == seeds["random"] for s in seeds.values())
    assert [(j.method, j.seed) for j in jobs if j.record] == [
        (settings.kinet_method, settings.first_seed)
    ]
    cells = [
        j for j in make_jobs(settings, settings.conditions()) if j.condition.role != "comparison"
    ]
    assert {j.condition.name for j in cells} == {"n2_geom_train", "n2_geom_gen"}
    assert {j.method for j in cells} == {settings.kinet_method}
    assert not any(j.record for j in cells)  # videos come from the comparison only


def fake_episode(job: Job, settings: RearrangementSettings) -> EpisodeResult:
    """An episode outcome determined by its method and seed, as a real episode's is."""
    rng = np.random.default_rng([job.seed, len(job.method)])
    distances = np.sort(rng.uniform(0, 0.1, settings.task.num_steps + 1))[::-1]
    return EpisodeResult(job.method, job.seed, distances, bool(distances[-1] < 0.02), False)


def fake_episodes(jobs: list[Job], settings: RearrangementSettings, model: object) -> list:
    """A stand-in of ``run_jobs``: :func:`fake_episode` of each job."""
    return [fake_episode(job, settings) for job in jobs]


class CountingEpisodes:
    """A stand-in of ``run_jobs``: fake episodes, the names of those it ran, and a Ctrl-C
    (KeyboardInterrupt) instead of episode number ``interrupt_at``."""

    def __init__(self, interrupt_at: int | None = None) -> None:
        self.ran: list[str] = []
        self.interrupt_at = interrupt_at

    def __call__(self, jobs: list[Job], settings: RearrangementSettings, model: object) -> list:
        results = []
        for job in jobs:
            if len(self.ran) == self.interrupt_at:
                raise KeyboardInterrupt
            self.ran.append(job.name)
            results.append(fake_episode(job, settings))
        return results


def test_an_interrupted_evaluation_resumes_from_its_stored_episodes(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    settings = RearrangementSettings(episodes=3, methods=("random", "oracle"), workers=1)
    monkeypatch.setattr(runner, "run_jobs", fake_episodes)
    straight = run_rearrangement(None, settings).summary()
    first, second = CountingEpisodes(interrupt_at=2), CountingEpisodes()
    monkeypatch.setattr(runner, "run_jobs", first)
    with pytest.raises(KeyboardInterrupt):
        run_rearrangement(None, settings, store_dir=tmp_path)
    monkeypatch.setattr(runner, "run_jobs", second)
    assert run_rearrangement(None, settings, store_dir=tmp_path).summary() == straight
    assert len(first.ran) == 2 and len(second.ran) == 4  # the stored episodes did not rerun
    assert not set(first.ran) & set(second.ran)


def test_stored_episodes_round_trip_and_belong_to_one_model_and_settings(
    tmp_path: Path, tiny_kinet
) -> None:
    settings = RearrangementSettings(episodes=2)
    rng = np.random.default_rng(0)
    result = EpisodeResult(
        "kinet_graph", 10_001, rng.uniform(size=5), True, False, rng.uniform(size=5),
        frames=[rng.integers(0, 255, (8, 8, 3), dtype=np.uint8) for _ in range(5)],
        keypoints=[rng.uniform(-1, 1, (4, 2)) for _ in range(5)],
        goal_pixels=rng.integers(0, 255, (8, 8, 3), dtype=np.uint8),
        goal_keypoints=rng.uniform(-1, 1, (4, 2)),
    )  # fmt: skip
    EpisodeStore(tmp_path, settings, tiny_kinet(0)).save("comparison/kinet_graph/seed10001", result)
    loaded = EpisodeStore(tmp_path, settings, tiny_kinet(0)).load(
        "comparison/kinet_graph/seed10001"
    )
    assert loaded is not None and (loaded.method, loaded.seed) == (result.method, result.seed)
    assert (loaded.success, loaded.unstable) == (True, False)
    for name in ("distances", "goal_ssim", "frames", "keypoints", "goal_pixels", "goal_keypoints"):
        np.testing.assert_array_equal(
            np.asarray(getattr(loaded, name)), np.asarray(getattr(result, name))
        )
    other_weights = EpisodeStore(tmp_path, settings, tiny_kinet(1))
    other_budget = replace(settings, planner={**settings.planner, "num_candidates": 8})
    other_settings = EpisodeStore(tmp_path, other_budget, tiny_kinet(0))
    assert other_weights.load("comparison/kinet_graph/seed10001") is None
    assert other_settings.load("comparison/kinet_graph/seed10001") is None
    # More episodes, other methods or another worker count run the same episodes: reused.
    more = replace(settings, episodes=100, methods=("kinet_graph",), workers=1, num_objects=(2,))
    assert EpisodeStore(tmp_path, more, tiny_kinet(0)).load("comparison/kinet_graph/seed10001")


def test_batches_keep_the_order_and_never_mix_conditions_or_methods() -> None:
    settings = RearrangementSettings(episodes=5, methods=("random", "oracle"), num_objects=(2,))
    jobs = make_jobs(settings, settings.conditions())
    groups = runner.batches(jobs, 2)
    assert [job for group in groups for job in group] == jobs
    assert all(1 <= len(group) <= 2 for group in groups)
    assert all(len({(j.condition, j.method) for j in group}) == 1 for group in groups)
    assert [len(g) for g in groups[:3]] == [2, 2, 1]  # 5 random episodes, then the oracle's
    assert runner.batches(jobs, 1) == [[job] for job in jobs]


def test_batched_evaluation_gives_the_same_summary_as_one_episode_at_a_time(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    monkeypatch.setattr(runner, "run_jobs", fake_episodes)
    single = RearrangementSettings(episodes=5, methods=("random", "oracle"), workers=1)
    batched = RearrangementSettings(
        episodes=5, methods=("random", "oracle"), workers=1, batch_episodes=3
    )
    assert run_rearrangement(None, batched).summary() == run_rearrangement(None, single).summary()
