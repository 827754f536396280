"""``zoo pipeline``: the whole suite in one command, each stage the ordinary ``zoo`` command.

``config.py`` says what a run makes, ``stages.py`` which commands make it, ``checks.py`` how an
output is verified, ``runner.py`` when a stage is skipped or run again, ``report.py`` the report.
Only ``cli`` is imported with ``zoo``: ``zoo --help`` must not load torch.
"""

from zoo.pipeline.cli import register

__all__ = ["register"]
