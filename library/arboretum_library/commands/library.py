"""``arboretum library``: look into, search, prune, export and import an example library.

    arboretum library info LIB
    arboretum library list LIB
    arboretum library search LIB WORDS... [--species S] [--limit N]
    arboretum library show LIB ID
    arboretum library delete LIB ID
    arboretum library export LIB ARCHIVE
    arboretum library import ARCHIVE LIB [--on-conflict skip|replace|rename]

Every subcommand takes ``--json``. Missing or foreign libraries and archives exit 2 with one line.
Actions that other installed packages add (the server's ``build``) are listed after these;
``arboretum library ACTION --help`` shows each action's options.
"""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

from arboretum_library.cli import add_json_flag, counted, emit, register_extensions, tell


def register(subparsers: Any) -> None:
    parser = subparsers.add_parser("library", help="inspect, search, export and import example libraries",
                                   description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = parser.add_subparsers(dest="action", metavar="ACTION", required=True)
    for name, help_ in (("info", "counts per species and tag, size on disk"),
                        ("list", "every example with its species, lobes, curvature and tags")):
        p = sub.add_parser(name, help=help_)
        p.add_argument("library", metavar="LIB")
    p = sub.add_parser("search", help="examples matching keywords, best first")
    p.add_argument("library", metavar="LIB")
    p.add_argument("words", nargs="*", metavar="WORD", help="tags (dense, sparse, straight, curved), species or text")
    p.add_argument("--species", help="only this species")
    p.add_argument("--limit", type=int, help="at most N results")
    for name, help_ in (("show", "one example's metadata"), ("delete", "remove one example")):
        p = sub.add_parser(name, help=help_)
        p.add_argument("library", metavar="LIB")
        p.add_argument("id", metavar="ID")
    p = sub.add_parser("export", help="the whole library into one .tar archive")
    p.add_argument("library", metavar="LIB")
    p.add_argument("archive", metavar="ARCHIVE")
    p = sub.add_parser("import", help="an archive into a library (created if missing)")
    p.add_argument("archive", metavar="ARCHIVE")
    p.add_argument("library", metavar="LIB")
    p.add_argument("--on-conflict", choices=("skip", "replace", "rename"), default="skip",
                   help="what to do with an id the library already has (default: skip)")
    for p in sub.choices.values():
        add_json_flag(p)
        p.set_defaults(func=run)
    own = set(sub.choices)
    register_extensions(sub, "arboretum.library_commands")
    extra = "".join(f"    {usage_line(f'arboretum library {name}', p)}\n"
                    for name, p in sub.choices.items() if name not in own)
    if _LAST_USAGE not in __doc__:  # a developer's edit of the docstring: fail in every CLI test, not silently
        raise RuntimeError("commands/library.py: _LAST_USAGE must be the docstring's last usage line")
    parser.description = __doc__.replace(_LAST_USAGE, _LAST_USAGE + extra)


_LAST_USAGE = "    arboretum library import ARCHIVE LIB [--on-conflict skip|replace|rename]\n"
"""The last line of the usage block in this module's docstring: extension actions go after it."""


def usage_line(prog: str, parser: argparse.ArgumentParser) -> str:
    """A one-line usage of ``parser`` run as ``prog``: its positionals, its required options and
    ``[options]`` when it has others ("arboretum library build SCAN... --library LIB [options]")."""
    words, optional = [prog], False
    for a in parser._actions:
        name = a.metavar if isinstance(a.metavar, str) else a.dest.upper()
        if not a.option_strings:
            words.append({"+": f"{name}...", "*": f"[{name}...]", "?": f"[{name}]"}.get(a.nargs, name))
        elif a.required:
            words.append(f"{a.option_strings[-1]} {name}" if a.nargs != 0 else a.option_strings[-1])
        elif not isinstance(a, argparse._HelpAction):
            optional = True
    return " ".join(words + ["[options]"] * optional)


def run(args: argparse.Namespace) -> int:
    actions = {"info": _info, "list": _list, "search": _search, "show": _show, "delete": _delete,
               "export": _export, "import": _import}
    data, text = actions[args.action](args)
    emit(args, data, text)
    return 0


def _open(path: str, readonly: bool = True, create: bool = False):
    """The library at ``path``. Writers wait for another process writing it as long as it takes, saying
    so on stderr (Ctrl-C stops them). A reader finding the catalog missing or damaged rebuilds it from
    the example folders as a writer would (the damaged file is kept aside) and says so on stderr; when
    it cannot write the library, one error names the file and what to do (``Library.open_reading``)."""
    from arboretum_library.store import Library

    if readonly:
        lib = Library.open_reading(path, lock_timeout=None, on_wait=tell)
    else:
        lib = Library.open(path, create, lock_timeout=None, on_wait=tell)
    r = lib.recovered
    if r.catalog_problem:
        kept = f"; the damaged file is kept as {r.catalog_kept}" if r.catalog_kept else ""
        tell(f"the catalog {lib.root / 'catalog.sqlite'} {r.catalog_problem}: rebuilt it from the example "
              f"folders ({len(lib)} examples{kept})")
    return lib


def _counts(counts: dict[str, int]) -> str:
    return ", ".join(f"{k} {v}" for k, v in counts.items()) or "-"


def _info(args: argparse.Namespace) -> tuple[dict, str]:
    with _open(args.library) as lib:
        info = lib.info()
    text = (f"library {info['path']} (schema {info['schema']})\n"
            f"  examples: {info['examples']}   size: {info['size_bytes'] / 1e6:.2f} MB\n"
            f"  species:  {_counts(info['species'])}\n"
            f"  tags:     {_counts(info['tags'])}")
    return info, text


def _row(e) -> dict:
    d = e.descriptors
    return {"id": e.id, "species": e.species, "lobes": d.lobe_count, "curvature": round(d.curvature, 4),
            "length": round(d.length, 4), "tags": list(e.tags), "source": e.source}


def _table(rows: list[dict], extra: str = "") -> str:
    if not rows:
        return "(no examples)"
    width = max(len(r["id"]) for r in rows)
    head = f"{'id':<{width}}  {'species':<12} lobes  curv.  tags"
    tags = max(len(" ".join(r["tags"])) for r in rows)
    lines = [f"{r['id']:<{width}}  {r['species']:<12} {r['lobes']:>5}  {r['curvature']:5.2f}  "
             f"{' '.join(r['tags']):<{tags}}  {r.get(extra, '')}".rstrip() for r in rows]
    return "\n".join([head, *lines])


def _list(args: argparse.Namespace) -> tuple[dict, str]:
    with _open(args.library) as lib:
        rows = [_row(e) for e in lib.entries()]
    return {"examples": rows, "count": len(rows)}, _table(rows)


def _search(args: argparse.Namespace) -> tuple[dict, str]:
    from arboretum_library.errors import InputError

    if args.limit is not None and args.limit < 1:
        raise InputError(f"--limit must be at least 1, got {args.limit}")
    with _open(args.library) as lib:
        hits = lib.search(args.words, args.limit, species=args.species)
        entries = {e.id: e for e in lib.entries(species=args.species)}  # one pass, not one per hit
        rows = [{**_row(entries[h.id]), "score": round(h.score, 4), "matched": list(h.matched)}
                for h in hits]
    for r in rows:
        r["why"] = f"score {r['score']:.2f}: {' '.join(r['matched']) or 'all'}"
    text = _table(rows, "why")
    data = {"query": args.words, "species": args.species,
            "hits": [{k: v for k, v in r.items() if k != "why"} for r in rows]}
    return data, text


def _show(args: argparse.Namespace) -> tuple[dict, str]:
    import dataclasses

    with _open(args.library) as lib:
        e = lib.entry(args.id)
        example = lib.get(args.id)
    s, p = example.structure, example.provenance
    data = {**_row(e), "descriptors": dataclasses.asdict(e.descriptors), "source_sha256": e.source_sha256,
            "parameters": dict(p.parameters), "branches": len(s.branches), "lobes": len(s.lobes),
            "points": len(s.points), "created": e.created, "content_sha256": e.content_sha256,
            "size_bytes": e.size_bytes}
    d = e.descriptors
    text = (f"{e.id}  ({e.species}, from {e.source})\n"
            f"  tags: {' '.join(e.tags) or '-'}\n"
            f"  lobes {d.lobe_count}, curvature {d.curvature:.3f} rad, length {d.length:.3f} m, "
            f"spread {d.spread:.3f} m, height {d.height:.3f} m\n"
            f"  {len(s.branches)} branches, {len(s.points)} points, {e.size_bytes} bytes, added {e.created}")
    return data, text


def _delete(args: argparse.Namespace) -> tuple[dict, str]:
    with _open(args.library, readonly=False) as lib:
        lib.delete(args.id)
        left = len(lib)
    return {"deleted": args.id, "examples": left}, f"deleted {args.id} ({left} examples left)"


def _export(args: argparse.Namespace) -> tuple[dict, str]:
    from arboretum_library.outputs import check_output
    from arboretum_library.progress import StatusLine

    # before the library is opened (which may rebuild its catalog): an ARCHIVE inside the library
    # would replace one of its files, one in a missing folder would fail after the work
    check_output(args.archive, "ARCHIVE", libraries=[args.library])
    with _open(args.library) as lib:
        out = lib.export_archive(args.archive, progress=StatusLine())
    return out, f"exported {counted(out['examples'], 'example')} to {out['archive']} ({out['size_bytes']} bytes)"


def _import(args: argparse.Namespace) -> tuple[dict, str]:
    from arboretum_library.archive import apply_archive, check_archive
    from arboretum_library.progress import StatusLine

    checked = check_archive(Path(args.archive))  # the whole archive, before the library is touched
    with _open(args.library, readonly=False, create=True) as lib:
        report = apply_archive(lib, checked, args.on_conflict, progress=StatusLine())
    data = report.as_dict()
    text = (f"imported {args.archive} into {args.library}: added {len(report.added)}, "
            f"replaced {len(report.replaced)}, renamed {len(report.renamed)}, skipped {len(report.skipped)}")
    return data, text
