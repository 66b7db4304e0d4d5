"""Policies ("agents" here; the robot is in `robots/`, the controller that carries out their
decisions in `control/`): one folder per policy with its agent, networks, dataset
collection and training, and what they all share: the agent interface (`base.py`,
`interface.py`) and the registry of agent names built from the folders (`registry.py`)."""
