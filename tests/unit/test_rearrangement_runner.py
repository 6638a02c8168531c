"""Tests for the runner's jobs (no simulation)."""

from __future__ import annotations

from kinet_rl.rearrangement.runner import make_jobs
from kinet_rl.rearrangement.settings import RearrangementSettings


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
