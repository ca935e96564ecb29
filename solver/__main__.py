"""``python -m solver``."""

from .cli import main

raise SystemExit(main())
