"""What the commands of the command line share: argparse types (positive numbers, whole numbers,
comma-separated lists), the --scheduler option, the default output folder, and the lines that report
a batch of runs and its failures."""

from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path

from .base.names import safe_name

__all__ = ["positive_float", "whole", "positive_int", "csv_list", "add_scheduler", "scheduler_of", "batch_line",
           "report_failures", "warn", "out_folder"]


def positive_float(text: str) -> float:
    try:
        v = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"must be a number of seconds, got {text!r}") from None
    if not v > 0:
        raise argparse.ArgumentTypeError(f"must be > 0, got {text!r}")
    return v


def whole(lowest: int):
    """argparse type: a whole number >= lowest."""
    def parse(text: str) -> int:
        try:
            v = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"must be a whole number, got {text!r}") from None
        if v < lowest:
            raise argparse.ArgumentTypeError(f"must be >= {lowest}, got {text!r}")
        return v
    return parse


positive_int = whole(1)


def add_scheduler(p) -> None:
    p.add_argument("--scheduler", default=None, metavar="ADDRESS",
                   help="run on Dask: tcp://HOST:PORT of a running scheduler, or local:N for a LocalCluster of N "
                        "processes (default: $FLEXMECH_SCHEDULER, else the local process pool; needs "
                        "pip install 'flexmech[cluster]'; see docs/cluster.md)")


def scheduler_of(args):
    """--scheduler, else $FLEXMECH_SCHEDULER unless --jobs asks for the local pool, else None (local pool)."""
    if args.scheduler:
        return args.scheduler
    return None if args.jobs is not None else (os.environ.get("FLEXMECH_SCHEDULER") or None)


def batch_line(b, what: str = "runs") -> str:
    return (f"{len(b.results)} {what} ({b.computed} computed, {b.cached} cached, {len(b.failed)} failed, "
            f"{b.retries} retried) in {b.wall_s:.1f} s on {b.executor or f'{b.jobs} process(es)'}")


def report_failures(reasons, total: int, what: str = "runs") -> int:
    """Each distinct failure reason with its count on stderr; the exit code (3 when any run failed)."""
    if not reasons:
        return 0
    print(f"flexmech: error: {sum(n for _, n in reasons)} of {total} {what} failed (the others are kept):",
          file=sys.stderr)
    for reason, n in reasons:
        print(f"  {n} x {reason}", file=sys.stderr)
    return 3


def warn(messages) -> None:
    for m in messages:
        print(f"flexmech: warning: {m}", file=sys.stderr)


def out_folder(args, suffix: str):
    """--out as given (a string: an empty one is refused by the result folder), else
    results/<case file stem>-<suffix> (the stem made a safe file name)."""
    return args.out if args.out is not None else Path("results") / f"{safe_name(Path(args.case).stem)}-{suffix}"


def csv_list(kind):
    def parse(text: str) -> list:
        try:
            vals = [kind(x) for x in text.split(",") if x.strip()]
        except ValueError:
            raise argparse.ArgumentTypeError(f"must be a comma-separated list of {kind.__name__}s, got {text!r}") from None
        if not vals:
            raise argparse.ArgumentTypeError("must not be empty")
        return vals
    return parse
