"""The reporting wing of ``bench``: tables, figures, claims and PDFs from a results folder alone.

:mod:`~bench.reporting.build` (``python -m bench.report``), :mod:`~bench.reporting.tables`,
:mod:`~bench.reporting.figures`, :mod:`~bench.reporting.claims`, :mod:`~bench.reporting.dataset_report`,
Table 2's accuracy join (:mod:`~bench.reporting.accuracy`), and the pages derived from several reports
(:mod:`~bench.reporting.margins`, :mod:`~bench.reporting.cards`). It reads what the harness wrote
(and may import the harness's declarations: axes, the results schema, the images' layout); the
harness never imports it.
"""
