"""The parts of the ``quadsitl`` command line that :mod:`quadsitl.cli` composes: the
options several subcommands share (``options.py``), and ``quadsitl sim``'s options
(``sim_options.py``) apart from how they become a running simulator (``sim_setup.py``).
"""
