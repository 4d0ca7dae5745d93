"""The world an episode drives in, before any simulation: route files (:mod:`~icrsumo.world.routes`),
road networks (:mod:`~icrsumo.world.networks`), routing and its junction passes
(:mod:`~icrsumo.world.routing`), background traffic (:mod:`~icrsumo.world.traffic`), the conversion of
route files into scenarios (:mod:`~icrsumo.world.convert`), the typed scenario manifest
(:mod:`~icrsumo.world.scenario`) and the ego's vehicle model (:mod:`~icrsumo.world.dynamics`).
Imports :mod:`icrsumo.core` alone."""
