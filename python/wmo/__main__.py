"""``python -m wmo``: the command line (see wmo.cli)."""
from .cli import main

raise SystemExit(main())
