"""Command-line options several ``dvrk-gym`` commands share: which instrument, what camera, progress."""

from __future__ import annotations

import argparse


def add_instrument_options(parser: argparse.ArgumentParser, resolution: bool = True, note: str = "") -> None:
    """``--bias`` and ``--bias-seed`` (the simulated instrument), and ``--resolution`` (the endoscope's image size).

    Args:
        parser: the command's parser.
        resolution: also add ``--resolution W H`` (pixels).
        note: words added to each help text (such as when the option applies).
    """
    parser.add_argument("--bias", default="paper", help=f"cable bias preset: none, paper or severe{note} (default: %(default)s)")
    parser.add_argument("--bias-seed", type=int, default=0, help=f"which instrument to draw{note} (default: %(default)s)")
    if resolution:
        add_resolution_option(parser)


def add_resolution_option(parser: argparse.ArgumentParser) -> None:
    """``--resolution W H``: the endoscope's image size, pixels."""
    parser.add_argument(
        "--resolution",
        type=int,
        nargs=2,
        default=(1920, 1080),
        metavar=("W", "H"),
        help="endoscope image size in pixels (default: 1920 1080)",
    )


def add_progress_option(parser: argparse.ArgumentParser) -> None:
    """``--no-progress``: no progress bars."""
    parser.add_argument("--no-progress", action="store_true", help="no progress bars")
