"""Pick the Vulkan device SAPIEN renders with, before SAPIEN is first used.

SAPIEN renders through Vulkan and needs `VK_KHR_external_semaphore_fd`, which Mesa's
lavapipe lacks; SwiftShader (shipped in Debian's chromium packages) has it. On a machine
with a GPU render node we leave Vulkan alone so the real GPU is used. Otherwise we point the
Vulkan loader at a SwiftShader ICD, so nobody has to export variables by hand.

Environment overrides:
  CFVS_RENDER_DEVICE=gpu|swiftshader|none   force the choice (none: physics only, no
    camera observations).
  CFVS_SWIFTSHADER_ICD=/path/vk_swiftshader_icd.json   use this ICD file.
  CFVS_RENDER_LOG=/path/file   keep what the Vulkan driver prints (else it is dropped).
"""

from __future__ import annotations

import contextlib
import glob
import os
import sys
import warnings
from collections.abc import Iterator
from pathlib import Path

SWIFTSHADER_BACKEND = "swiftshader"
"""Name we register in ManiSkill's render-backend table for the SwiftShader device."""

_ICD_NAME = "vk_swiftshader_icd.json"
_state: dict[str, str] = {}


class RenderDeviceError(RuntimeError):
    """No Vulkan device SAPIEN can render with."""


def _has_gpu_node() -> bool:
    return bool(glob.glob("/dev/nvidia[0-9]*") or glob.glob("/dev/dri/renderD*"))


def swiftshader_icd_candidates() -> list[Path]:
    """Where the set-up command and Debian's chromium packages put the SwiftShader ICD."""
    out = []
    if os.environ.get("CFVS_SWIFTSHADER_ICD"):
        out.append(Path(os.environ["CFVS_SWIFTSHADER_ICD"]))
    out += [
        Path(sys.prefix) / "share" / "cfvs_maniskill" / "swiftshader" / _ICD_NAME,
        Path(os.environ.get("CFVS_CACHE") or Path.home() / ".cache" / "cfvs_maniskill")
        / "swiftshader"
        / _ICD_NAME,
        Path("/usr/lib/chromium") / _ICD_NAME,
    ]
    return out


def configure() -> str:
    """Choose the device once per process; returns "gpu", "swiftshader", "none" (forced) or
    "missing".

    Must run before SAPIEN creates its render system. Child processes inherit the
    environment variable we set, so workers need no extra step.
    """
    if "kind" in _state:
        return _state["kind"]
    # SAPIEN falls back to its bundled Vulkan loader, which works; its warning only confuses.
    warnings.filterwarnings("ignore", message="Failed to find system libvulkan")
    forced = os.environ.get("CFVS_RENDER_DEVICE", "").lower()
    if forced == "none":
        _state.update(kind="none")
    elif os.environ.get("VK_ICD_FILENAMES") and forced != "gpu":
        icd = os.environ["VK_ICD_FILENAMES"]
        kind = SWIFTSHADER_BACKEND if "swiftshader" in icd.lower() else "gpu"
        _state.update(kind=kind, icd=icd)
    elif forced == "gpu" or (forced != SWIFTSHADER_BACKEND and _has_gpu_node()):
        _state.update(kind="gpu")
    else:
        icd_path = next((p for p in swiftshader_icd_candidates() if p.is_file()), None)
        if icd_path is None:
            _state.update(kind="missing")
        else:
            os.environ["VK_ICD_FILENAMES"] = str(icd_path)
            _state.update(kind=SWIFTSHADER_BACKEND, icd=str(icd_path))
    if _state["kind"] == SWIFTSHADER_BACKEND:
        _register_maniskill_backend()
    return _state["kind"]


def _register_maniskill_backend() -> None:
    # ManiSkill splits a backend string on ':', so "pci:0" cannot be passed directly; a
    # name mapped to it survives the split. SwiftShader is the only device, i.e. pci:0.
    import mani_skill.envs.utils.system.backend as backend

    backend.render_backend_name_mapping[SWIFTSHADER_BACKEND] = "pci:0"


GPU_BACKENDS = ("gpu", "cuda", "sapien_cuda")
"""ManiSkill's names for a GPU render device: its stock scripts pass "gpu" by default."""


def render_backend(requested: str | None = None) -> str:
    """The `render_backend` argument for ManiSkill envs on this machine.

    None picks the device. A GPU backend requested on a machine without one (ManiSkill's
    scripts default to "gpu") falls back to SwiftShader with one warning, so the stock
    tools run with their default flags; "none" and explicit devices ("pci:0") pass through.
    """
    kind = configure()
    if requested == "none" or kind == "none":
        return "none"
    if kind == "missing":
        raise RenderDeviceError(missing_message())
    if requested is None:
        return SWIFTSHADER_BACKEND if kind == SWIFTSHADER_BACKEND else "gpu"
    if kind == SWIFTSHADER_BACKEND and requested in GPU_BACKENDS:
        if not _state.get("warned"):
            _state["warned"] = "1"
            warnings.warn(
                f"render_backend={requested!r} asks for a GPU, but this machine has none: "
                "rendering on SwiftShader (CPU Vulkan) instead",
                stacklevel=3,
            )
        return SWIFTSHADER_BACKEND
    return requested


def missing_message() -> str:
    tried = "\n  ".join(str(p) for p in swiftshader_icd_candidates())
    return (
        "No Vulkan device for SAPIEN's renderer: no GPU render node (/dev/dri/renderD*, "
        "/dev/nvidia*) and no SwiftShader ICD found. Looked for:\n  "
        f"{tried}\nRun `cfvs-maniskill setup-render` (it copies SwiftShader, a CPU Vulkan "
        "driver, from Debian's chromium-common package into your cache; scripts/setup.sh "
        "runs it), or set CFVS_SWIFTSHADER_ICD to a vk_swiftshader_icd.json, or "
        "CFVS_RENDER_DEVICE=none for physics without cameras."
    )


def describe() -> str:
    kind = configure()
    if kind == SWIFTSHADER_BACKEND:
        return f"rendering on SwiftShader (CPU Vulkan, {_state['icd']})"
    if kind == "gpu":
        return "rendering on the system's Vulkan GPU driver"
    if kind == "none":
        return "no rendering (CFVS_RENDER_DEVICE=none): physics only"
    return "no rendering device found: " + missing_message()


@contextlib.contextmanager
def driver_output_to_log() -> Iterator[None]:
    """Send what C code prints to stderr (SwiftShader's "UNSUPPORTED" lines while SAPIEN
    makes its device) to $CFVS_RENDER_LOG, else nowhere; Python's own messages, warnings
    and tracebacks still reach the terminal."""
    sys.stderr.flush()
    terminal = os.dup(2)
    with open(os.environ.get("CFVS_RENDER_LOG") or os.devnull, "a") as log:
        os.dup2(log.fileno(), 2)
    python_stderr, sys.stderr = sys.stderr, os.fdopen(os.dup(terminal), "w", buffering=1)
    try:
        yield
    finally:
        sys.stderr.close()
        sys.stderr = python_stderr
        os.dup2(terminal, 2)
        os.close(terminal)
