"""``bench.report.merge``: a module measured again replaces its own rows in the full run's table, in
place, and the table says which rows were measured when (session 23: the decomposition rows after
that session's speed changes, the rest from the last full run)."""

from bench.report import merge, table


def _row(module: str, name: str, median: float) -> dict:
    return {"module": module, "name": name, "median": median, "unit": "s", "target": None, "ratio": None,
            "ok": None, "baseline": "", "note": ""}


def test_a_partial_run_replaces_its_modules_rows_in_place_and_is_noted():
    full = {"when": "T0", "machine": {"cpus": 2, "python": "3.11"}, "failed_modules": [],
            "rows": [_row("bench_a", "a1", 1.0), _row("bench_b", "b1", 2.0), _row("bench_b", "b2", 3.0),
                     _row("bench_c", "c1", 4.0)]}
    partial = {"when": "T1", "rows": [_row("bench_b", "b1", 2.5), _row("bench_b", "b3", 5.0)]}
    out = merge(full, partial)
    assert [(r["name"], r["median"]) for r in out["rows"]] == [("a1", 1.0), ("b1", 2.5), ("b3", 5.0), ("c1", 4.0)]
    assert out["reruns"] == [{"modules": ["bench_b"], "when": "T1"}] and out["when"] == "T0"
    assert "Rows of bench_b measured again on T1 (`python -m bench b`)." in table(out)
    again = merge(out, {"when": "T2", "rows": [_row("bench_b", "b1", 2.4)]})
    assert again["reruns"] == [{"modules": ["bench_b"], "when": "T2"}]  # the older note of the same module goes


def test_a_rerun_note_says_where_it_ran():
    full = {"when": "T0", "machine": {"cpus": 2, "python": "3.11"}, "failed_modules": [],
            "rows": [_row("bench_a", "a1", 1.0), _row("bench_b", "b1", 2.0)]}
    out = merge(full, {"when": "T1", "rows": [_row("bench_b", "b1", 4.0)]}, "On a machine 2-4 times slower.")
    assert out["reruns"] == [{"modules": ["bench_b"], "when": "T1", "note": "On a machine 2-4 times slower."}]
    assert "(`python -m bench b`). On a machine 2-4 times slower." in table(out)
    assert "note" not in merge(full, {"when": "T1", "rows": [_row("bench_b", "b1", 4.0)]})["reruns"][0]
