"""fusion.evaluation: judging merges against ground truth — map-pair datasets on disk
(:mod:`~fusion.evaluation.pairs`), synthetic pairs (:mod:`~fusion.evaluation.synthetic`), the
records and summaries (:mod:`~fusion.evaluation.results`), the evaluation CLI
(:mod:`~fusion.evaluation.evaluate`, ``python -m fusion.evaluation``), topological
repeatability (:mod:`~fusion.evaluation.repeatability`), failure diagnosis
(:mod:`~fusion.evaluation.diagnose`) and the truth of maps that bend
(:mod:`~fusion.evaluation.bending`: fused maps judged against the world).

The merge methods themselves live in :mod:`fusion`; nothing there imports this package except
for the synthetic pairs its doctests and ``fusion``'s top level re-export.
"""
