"""``python -m fusion.evaluate``: the older spelling of ``python -m fusion.evaluation``, kept so
existing scripts keep working (the module is :mod:`fusion.evaluation.evaluate`)."""

import sys

from fusion.evaluation.evaluate import main

if __name__ == "__main__":
    sys.exit(main())
