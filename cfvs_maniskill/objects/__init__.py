"""Hole objects: YAML specs (`spec`), mesh + hole cut + convex decomposition (`build`), and the
library of specs found in asset directories (`library`)."""

from cfvs_maniskill.objects.spec import HoleSpec, HoleSpecError, load_spec

__all__ = ["HoleSpec", "HoleSpecError", "load_spec"]
