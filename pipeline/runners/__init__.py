"""One runner module per stage: what a command does, below its option parsing.

``pipeline/commands/<command>.py`` declares the command line (typer) and calls ``run_<stage>`` here;
a runner validates its inputs, estimates what it will allocate, calls the stage's kernels
(``stages/<stage>/``), and publishes the stage's artifact (``pipeline.artifacts``).
"""
