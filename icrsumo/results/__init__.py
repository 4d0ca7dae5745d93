"""What an evaluation leaves behind and reads back, without running anything: the episode log
(:mod:`~icrsumo.results.logs`), the results store (:mod:`~icrsumo.results.store`), the typed summary
(:mod:`~icrsumo.results.summary`) and the statistics behind it (:mod:`~icrsumo.results.aggregate`),
decision-level attribution (:mod:`~icrsumo.results.decisions`, :mod:`~icrsumo.results.attribution`)
and the guards' measurement (:mod:`~icrsumo.results.guards`). The writers of reports sit above it
(:mod:`icrsumo.reporting`), the evaluation that fills it above them."""
