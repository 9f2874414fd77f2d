"""``python -m fusion.evaluation``: the evaluation CLI (:func:`fusion.evaluation.evaluate.main`)."""

import sys

from fusion.evaluation.evaluate import main

sys.exit(main())
