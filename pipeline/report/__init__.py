"""The report stage: DIR/report.html and DIR/run.rrd from the artefacts of the stages before it."""
