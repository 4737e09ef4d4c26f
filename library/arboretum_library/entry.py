"""The ``arboretum`` console script: ``cli.main``, with a Ctrl-C while Python still loads it (argparse,
json, importlib.metadata: the first ~40 ms) ending as every other interruption does, with one line and
exit 130, instead of a traceback through the standard library's imports (session 19)."""

import atexit
import gc
import sys


def run() -> None:
    skip_exit_collection()
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


def skip_exit_collection() -> None:
    """Let the process end without the garbage collector's passes over every object: ``gc.freeze`` as the last
    exit handler (handlers run last registered first; call this first). Python's shutdown collects the whole
    heap several times while it clears the modules: after ``arboretum decompose`` (numba's registries, scipy,
    the decomposition) that took 0.4-0.5 s of a 2.5-3 s run on the development machine, after the output was
    printed (session 31). Exit handlers, ``weakref.finalize`` callbacks, the flushing of stdout and stderr and
    the freeing of objects no cycle holds all still happen; skipped are the finalizers of objects in reference
    cycles at exit, which Python does not promise to run (spack does the same, spack/spack#53020). For the
    command-line process only: never called by code that imports the library."""
    atexit.register(gc.freeze)
