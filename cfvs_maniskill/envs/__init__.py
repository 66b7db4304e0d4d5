"""Peg-in-hole environments: one ManiSkill env id per task file in `tasks/`."""
