"""Fixtures of the script tests, shared by every module here: the train command and one tiny trained run per test
module (:mod:`tests.scripts.tiny_run`), and the misuse cases' paths (:mod:`tests.scripts.cli_misuse`)."""

from .cli_misuse import misuse_paths
from .tiny_run import tiny_run, train

__all__ = ["misuse_paths", "tiny_run", "train"]
