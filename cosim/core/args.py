"""What every ``cosim`` subcommand shares, the CLI's own and those scenario
sections bring (``cosim.core.section.CliCommand``): the exit codes and the
argument types (each refuses a bad value with a message argparse prints as
a usage error, exit 2)."""

from __future__ import annotations

import argparse

#: 0 ok, 1 runtime failure, 2 usage or config error, 130 stopped by Ctrl-C
EXIT_OK, EXIT_FAIL, EXIT_USAGE, EXIT_INTERRUPTED = 0, 1, 2, 130


def positive_int_list(text: str) -> list[int]:
    try:
        vals = [int(x) for x in text.split(",") if x.strip()]
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"expected comma-separated whole numbers, got {text!r}") from None
    if not vals or any(v < 1 for v in vals):
        raise argparse.ArgumentTypeError(f"expected positive whole numbers, got {text!r}")
    return vals


def altitudes(text: str) -> list[float]:
    vals = [positive_float(x) for x in text.split(",") if x.strip()]
    if not vals or len(vals) > 50 or any(not 10.0 <= v <= 10_000.0 for v in vals):
        raise argparse.ArgumentTypeError(f"expected 1 to 50 comma-separated altitudes of 10 to "
                                         f"10000 m, got {text!r}")
    return vals


def positive_float(text: str) -> float:
    try:
        v = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number, got {text!r}") from None
    if not v > 0:
        raise argparse.ArgumentTypeError(f"expected a number > 0, got {text!r}")
    return v
