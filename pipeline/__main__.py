"""`python -m pipeline ...` is `robocal ...` (for checkouts the installed script does not point at)."""
from pipeline.cli import main

main()
