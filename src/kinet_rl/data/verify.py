"""Check datasets against their checksums: ``python -m kinet_rl.data.verify <path> [<path> ...]``.

Prints one report per dataset folder (:func:`kinet_rl.data.verify_dataset`): the episodes
checked, and the corrupt ones with their split. Exit status 0 when every dataset matches its
checksums, 1 when one is corrupt (an episode differs from its checksum, or its files are
truncated or unreadable), 2 when one cannot be verified (no dataset there, or no checksums
recorded: collected by an older kinet_rl).
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence
from pathlib import Path

from kinet_rl.data.storage import DatasetCorruptError, DatasetError
from kinet_rl.data.verification import verify_dataset

#: Exit statuses.
OK, CORRUPT, NOT_VERIFIED = 0, 1, 2


def verify_one(path: Path) -> tuple[int, str]:
    """The exit status and report line(s) of one dataset folder."""
    try:
        report = verify_dataset(path)
    except DatasetCorruptError as err:
        return CORRUPT, f"{path}: CORRUPT: {err}"
    except DatasetError as err:
        return NOT_VERIFIED, f"{path}: NOT VERIFIED: {err}"
    if not report.ok:
        return CORRUPT, report.summary()
    return (OK if report.checksums_present else NOT_VERIFIED), report.summary()


def main(argv: Sequence[str] | None = None) -> int:
    """Verifies each dataset folder named on the command line; returns the exit status."""
    parser = argparse.ArgumentParser(
        prog="python -m kinet_rl.data.verify",
        description="Check datasets against the checksums recorded when they were collected.",
        epilog="Exit status: 0 all match, 1 a dataset is corrupt, 2 one cannot be verified.",
    )
    parser.add_argument("paths", nargs="+", type=Path, metavar="path", help="<root>/<name>")
    statuses = set()
    for path in parser.parse_args(argv).paths:
        status, text = verify_one(path)
        print(text, flush=True)
        statuses.add(status)
    return CORRUPT if CORRUPT in statuses else max(statuses)


if __name__ == "__main__":
    sys.exit(main())
