"""Write the speed table of docs/evaluation.md from bench/results.json (so every figure has a command).

    python -m bench.report            # print the table
    python -m bench.report --update   # replace the block between the markers in docs/evaluation.md
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
    if results.get("failed_modules"):
        lines.append(f"\nModules that failed to run: {', '.join(results['failed_modules'])}.")
    return "\n".join(lines)


def main(argv: list[str]) -> int:
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
