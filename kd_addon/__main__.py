"""`python -m kd_addon render [scene.blend] --frames 1-24 --out DIR [...]` with the bpy module (see cli.py)."""

import sys

from .cli import main

sys.exit(main())
