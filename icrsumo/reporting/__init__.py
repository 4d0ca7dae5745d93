"""The files an evaluation's summary becomes (:class:`icrsumo.results.summary.Summary` in, text and
figures out), one writer per module:

* :mod:`~icrsumo.reporting.cells`: cells safe in Markdown, LaTeX and CSV; number formats;
* :mod:`~icrsumo.reporting.rows`: the results table's rows as text cells (Markdown, LaTeX, HTML);
* :mod:`~icrsumo.reporting.table_md`, :mod:`~icrsumo.reporting.table_csv`,
  :mod:`~icrsumo.reporting.table_tex`: results.md, results.csv, results.tex
  (:mod:`~icrsumo.reporting.tables`: the three at once);
* :mod:`~icrsumo.reporting.statistics`: statistics.md and statistics.csv;
* :mod:`~icrsumo.reporting.attribution`: attribution.md and its figures;
* :mod:`~icrsumo.reporting.figures`: the figures (the only matplotlib user, imported lazily, Agg);
* :mod:`~icrsumo.reporting.rollout`: the paired rollout figure;
* :mod:`~icrsumo.reporting.guard`: guard.md, its figure and the printed guard note;
* :mod:`~icrsumo.reporting.html` (with :mod:`~icrsumo.reporting.html_route` and
  :mod:`~icrsumo.reporting.trajectory`): report.html;
* :mod:`~icrsumo.reporting.write`: summary.json, the tables, episodes.csv, the figures and the
  leaderboard results files (as the run's scoring writes them, :mod:`icrsumo.scoring`).
"""
