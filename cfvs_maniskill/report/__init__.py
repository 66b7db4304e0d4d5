"""Tables and plots from result files: `python -m cfvs_maniskill.report DIR --out report/`."""
