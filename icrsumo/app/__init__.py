"""The application layer, on top of the library: the Python API (:mod:`~icrsumo.app.api`, exported
as ``icrsumo.evaluate`` ...), the Gymnasium environment (:mod:`~icrsumo.app.env`), episode replay
(:mod:`~icrsumo.app.show`), the agent checker (:mod:`~icrsumo.app.check_agent`) and the ``icrsumo``
command (:mod:`icrsumo.app.cli`, one module per subcommand), which nothing else imports."""
