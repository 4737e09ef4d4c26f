"""The ``arboretum`` console script: ``cli.main``, with a Ctrl-C while Python still loads it (argparse,
json, importlib.metadata: the first ~40 ms) ending as every other interruption does, with one line and
exit 130, instead of a traceback through the standard library's imports (session 19)."""

import sys


def run() -> None:
    try:
        from .cli import main
    except KeyboardInterrupt:
        command = next((w for w in sys.argv[1:] if not w.startswith("-")), "")
        print(f"{f'arboretum {command}'.rstrip()}: interrupted", file=sys.stderr, flush=True)
        if "--json" in sys.argv[1:]:  # as cli.fail prints it
            import json

            failure = {"command": command or "arboretum", "error": "interrupted", "exit": 130}
            print(json.dumps(failure, indent=2, sort_keys=True), flush=True)
        sys.exit(130)
    sys.exit(main())
