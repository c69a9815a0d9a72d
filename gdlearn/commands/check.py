"""``gdlearn check <exercise>``: run an exercise's tests against your stub, with readable feedback.

Prints one line per check (what it verifies) and, for a failure, what went wrong in words -- not a
traceback wall (``-v`` adds pytest's own output). Exit status 0 when every check passes, 1 when
some fail, 2 for an unknown exercise. See :mod:`gdlearn.teaching.exercises` and exercises/README.md.
"""
from __future__ import annotations

import sys


def add_parser(subparsers) -> None:
    p = subparsers.add_parser("check", help="check your solution of a book exercise",
                              description=__doc__.splitlines()[0])
    p.add_argument("name", nargs="?", help="exercise name (see --list), e.g. cosine-hemisphere")
    p.add_argument("--list", action="store_true", help="list the exercises and exit")
    p.add_argument("--solution", action="store_true",
                   help="test the reference solution instead of your stub (what CI does)")
    p.add_argument("-v", "--verbose", action="store_true", help="also show pytest's tracebacks")
    p.set_defaults(func=run)


def run(args) -> int:
    from gdlearn.teaching.exercises import EXERCISES_DIR, check, list_exercises

    names = list_exercises()
    if args.list or not args.name:
        if not args.list:
            print("gdlearn check: name an exercise, e.g. `gdlearn check cosine-hemisphere`", file=sys.stderr)
        for name in names:
            first = (EXERCISES_DIR / name / "README.md").read_text().splitlines()[0].lstrip("# ")
            print(f"{name:24s} {first}")
        return 0 if args.list else 2
    try:
        report = check(args.name, solution=args.solution, verbose=args.verbose)
    except (ValueError, FileNotFoundError) as err:
        print(f"gdlearn check: {err}", file=sys.stderr)
        return 2
    print(report.text())
    return 0 if report.ok else 1
