"""The workers take the longest routes first (issue 48: no worker left alone with a long episode
at the end of a run); the order changes no episode (the worker-count and backend tests compare
whole folders byte for byte)."""

from icrsumo.evaluation.plan import Job, longest_first


def _job(route: str, length: float, family: str = "baseline", k: int = 0) -> Job:
    return Job("a", "a", route, family, k, 2026, "sc", "in", route_length=length)


def test_longest_routes_first_ties_in_planned_order():
    jobs = [_job("r1", 100.0), _job("r1", 100.0, "noise", 0), _job("r2", 900.0), _job("r3", 300.0),
            _job("r2", 900.0, "noise", 1)]
    got = longest_first(jobs)
    assert [(j.route_id, j.family) for j in got] == [("r2", "baseline"), ("r2", "noise"), ("r3", "baseline"),
                                                      ("r1", "baseline"), ("r1", "noise")]
    assert sorted(got, key=jobs.index) == jobs  # a permutation
    assert _job("r1", 5.0) == _job("r1", 7.0)  # the length is not part of the job's identity
