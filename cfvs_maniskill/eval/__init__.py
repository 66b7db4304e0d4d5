"""Evaluation at scale: every (task, agent, object, initial error, episode) is a job with a
fixed seed; results append to one JSON-lines file, so a killed run resumes where it was.
`python -m cfvs_maniskill.eval --help`."""
