"""``gdlearn render | effects | compare | check``.

Each sub-command lives in its own module under :mod:`gdlearn.commands` with ``add_parser(sub)`` and
``run(args) -> int``. Scene errors are printed as one message (file, line, fix) with exit status 2,
never as a traceback.
"""
from __future__ import annotations

import argparse
import importlib
import sys

COMMANDS = ("render", "effects", "compare", "check")


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="gdlearn", description=__doc__.splitlines()[0])
    sub = p.add_subparsers(dest="command", required=True)
    for name in COMMANDS:
        importlib.import_module(f"gdlearn.commands.{name}").add_parser(sub)
    return p


def main(argv=None) -> int:
    from gdlearn.scene.model import SceneError

    args = build_parser().parse_args(argv)
    try:
        return int(args.func(args) or 0)
    except SceneError as err:
        print(f"gdlearn: {err}", file=sys.stderr)
        return 2
