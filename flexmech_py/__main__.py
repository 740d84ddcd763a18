"""``python -m flexmech_py`` is the ``flexmech`` command."""

from .cli import main

raise SystemExit(main())
