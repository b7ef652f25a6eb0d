"""The ``helireach`` command (:mod:`.main`) and one module per subcommand: ``plan`` (:mod:`.plan`),
``envelope`` (:mod:`.envelope`), ``bringup`` (:mod:`.bringup`), ``replay`` (:mod:`.replay`),
``display`` (:mod:`.display`), plus the demo (:mod:`.demo`, ``python -m helireach_ros.cli.demo``).
Argument parsing and exit codes only: each handler calls the core, ROS or display layer, importing it
lazily so ``helireach --help`` stays fast.
"""
