"""The ``dvrk-gym`` command line: one module per command group, each thin (parse, call the library, print).

Nothing in the library imports this package; ``dvrk_gym.cli.main:main`` is the console script.
"""
