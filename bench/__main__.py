"""Run every benchmark module, print a table, write bench/results.json.

    python -m bench            # all
    python -m bench decompose  # only modules whose name contains 'decompose'
"""

from __future__ import annotations

import importlib
import json
import os
import platform
import sys
import time
import traceback
from pathlib import Path

HERE = Path(__file__).parent


def main(argv: list[str]) -> int:
    os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")
    names = sorted(p.stem for p in HERE.glob("bench_*.py"))
    if argv:
        names = [n for n in names if any(a in n for a in argv)]
    rows, failures = [], []
    for name in names:
        print(f"== {name}", file=sys.stderr, flush=True)
        try:
            mod = importlib.import_module(f"bench.{name}")
            for row in mod.run():
                rows.append({"module": name, **row.as_dict()})
                print(f"   {row.name}: {row.median:.4g} {row.unit}", file=sys.stderr, flush=True)
        except Exception:
            failures.append(name)
            traceback.print_exc()
    print_table(rows)
    out = {
        "when": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()),
        "machine": {"cpus": os.cpu_count(), "python": platform.python_version(), "platform": platform.platform()},
        "rows": rows,
        "failed_modules": failures,
    }
    path = HERE / "results.json" if not argv else HERE / "results.partial.json"
    path.write_text(json.dumps(out, indent=2) + "\n")
    print(f"wrote {path}", file=sys.stderr)
    return 1 if failures else 0


def print_table(rows: list[dict]) -> None:
    head = f"{'benchmark':<52} {'median':>11} {'target':>11} {'ok':>4} {'ratio':>8}  baseline"
    print(head)
    print("-" * len(head))
    for r in rows:
        tgt = "" if r["target"] is None else f"{r['target']:.4g} {r['unit']}"
        ok = {True: "yes", False: "NO", None: ""}[r["ok"]]
        ratio = "" if r["ratio"] is None else f"{r['ratio']:.3g}"
        print(f"{r['name']:<52} {r['median']:>8.4g} {r['unit']:<2} {tgt:>11} {ok:>4} {ratio:>8}  {r['baseline']}")


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
