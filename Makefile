bench:  ## every benchmark figure -> benchmarks/RESULTS.md
	.venv/bin/python -m benchmarks.run

test:  ## set-up, lint, the whole test suite (what CI runs)
	bash scripts/test.sh

.PHONY: bench test
