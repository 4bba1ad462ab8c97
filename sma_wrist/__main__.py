"""``python3 -m sma_wrist ...`` is ``sma-wrist ...`` (when the scripts directory is not on PATH)."""

from sma_wrist.cli import main

raise SystemExit(main())
