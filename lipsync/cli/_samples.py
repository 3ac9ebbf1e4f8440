"""``--samples on|off`` (render, dub): a bank's real mouth samples, or one picture per viseme."""

from __future__ import annotations

SAMPLES_HELP = ("a bank made from video: show a real mouth sample per frame, chosen from its footage (on), or "
                "morph one picture per viseme (off; default: bank.yaml's samples:, on when the bank has them)")


def add_samples_option(p) -> None:
    p.add_argument("--samples", choices=("on", "off"), default=None, help=SAMPLES_HELP)
