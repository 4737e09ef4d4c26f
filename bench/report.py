"""Write the speed table of docs/evaluation.md from bench/results.json (so every figure has a command).

    python -m bench.report            # print the table
    python -m bench.report --update   # replace the block between the markers in docs/evaluation.md
    python -m bench.report --merge    # put bench/results.partial.json's modules (``python -m bench NAME``)
                                      # into bench/results.json in place of the full run's, noting when
    python -m bench.report --merge --note "TEXT"   # ... and why or where (e.g. another machine's run)
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

HERE = Path(__file__).parent
DOC = HERE.parent / "docs" / "evaluation.md"
BEGIN, END = "<!-- bench:begin -->", "<!-- bench:end -->"


def _fmt(value: float | None, unit: str) -> str:
    if value is None:
        return ""
    if unit == "s" and value < 1:
        return f"{value * 1e3:.3g} ms"
    return f"{value:.3g} {unit}".strip()


def table(results: dict) -> str:
    lines = [
        f"Measured by `make bench` on {results['when']} ({results['machine']['cpus']} cores, Python "
        f"{results['machine']['python']}); medians unless the row says p95.",
        "",
        "| benchmark | measured | target | met | ratio | baseline (same run) |",
        "|---|---:|---:|:---:|---:|---|",
    ]
    for r in results["rows"]:
        met = {True: "yes", False: "**no**", None: ""}[r["ok"]]
        ratio = "" if r["ratio"] is None else f"{r['ratio']:.3g}"
        name = r["name"] + (" (p95)" if r.get("note", "").startswith("p95") else "")
        lines.append(f"| {name} | {_fmt(r['median'], r['unit'])} | {_fmt(r['target'], r['unit'])} | {met} "
                     f"| {ratio} | {r['baseline']} |")
    for rerun in results.get("reruns", []):
        note = f" {rerun['note']}" if rerun.get("note") else ""
        lines.append(f"\nRows of {', '.join(rerun['modules'])} measured again on {rerun['when']} "
                     f"(`python -m bench {' '.join(m.removeprefix('bench_') for m in rerun['modules'])}`).{note}")
    if results.get("failed_modules"):
        lines.append(f"\nModules that failed to run: {', '.join(results['failed_modules'])}.")
    return "\n".join(lines)


def merge(full: dict, partial: dict, note: str = "") -> dict:
    """``full`` with the rows of every module in ``partial`` replaced by ``partial``'s, in the full run's
    order, and the rerun recorded (``reruns``, with ``note`` when given: e.g. that it ran on another
    machine): a module measured again after a change keeps the rest of the table, whose rows stay as their
    run measured them."""
    modules = sorted({r["module"] for r in partial["rows"]})
    fresh = {m: [r for r in partial["rows"] if r["module"] == m] for m in modules}
    rows, placed = [], set()
    for r in full["rows"]:
        if r["module"] not in fresh:
            rows.append(r)
        elif r["module"] not in placed:
            rows.extend(fresh[r["module"]])
            placed.add(r["module"])
    rows.extend(r for m in modules if m not in placed for r in fresh[m])
    reruns = [x for x in full.get("reruns", []) if not set(x["modules"]) <= set(modules)]
    rerun = {"modules": modules, "when": partial["when"]} | ({"note": note} if note else {})
    return {**full, "rows": rows, "reruns": reruns + [rerun]}


def main(argv: list[str]) -> int:
    if "--merge" in argv:
        note = argv[argv.index("--note") + 1] if "--note" in argv[:-1] else ""
        merged = merge(json.loads((HERE / "results.json").read_text()),
                       json.loads((HERE / "results.partial.json").read_text()), note)
        (HERE / "results.json").write_text(json.dumps(merged, indent=2) + "\n")
        print(f"merged {HERE / 'results.partial.json'} into {HERE / 'results.json'}")
        return 0
    results = json.loads((HERE / "results.json").read_text())
    block = table(results)
    if "--update" not in argv:
        print(block)
        return 0
    doc = DOC.read_text()
    head, rest = doc.split(BEGIN, 1)
    _, tail = rest.split(END, 1)
    DOC.write_text(f"{head}{BEGIN}\n{block}\n{END}{tail}")
    print(f"updated {DOC}")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
