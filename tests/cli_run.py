"""Running the command line in-process for a test: one helper for every CLI test module."""

from __future__ import annotations

from arshadow.cli import main


def run_cli(capsys, *argv) -> tuple[int, str, str]:
    """``arshadow ARGV...`` in this process: ``(exit status, stdout, stderr)``; an argparse exit is a status."""
    try:
        code = main([str(a) for a in argv])
    except SystemExit as exc:  # argparse: usage errors exit 2, --help exits 0
        code = exc.code if isinstance(exc.code, int) else 1
    cap = capsys.readouterr()
    return code, cap.out, cap.err
