"""The ```sh blocks of the pages tests/doc_runner.py's GROUPS gives this file, run as printed (tests/doc_runner.py)."""

from doc_runner import block_test, scratch  # noqa: F401 (the runner's fixture)

test_block_runs_as_printed = block_test(__file__)
