"""Makes the TACAN front-end tests' shared helpers importable as ``_tacan_fe_util``.

``tests`` is not a package, so pytest's default ``prepend`` import mode already puts this
directory on ``sys.path``; inserting it here as well keeps the import working under
``--import-mode=importlib`` too.
"""
import sys
from pathlib import Path

_HERE = str(Path(__file__).resolve().parent)
if _HERE not in sys.path:
    sys.path.insert(0, _HERE)
