"""`cfvs-maniskill setup-render`: a Vulkan driver for SAPIEN's renderer on a machine without a
GPU, for users who `pip install` the package into an environment of their own.

SAPIEN renders through Vulkan and needs `VK_KHR_external_semaphore_fd`, which Mesa's
lavapipe lacks; SwiftShader, the CPU Vulkan driver Chromium ships, has it
(the notes in README.md, "Rendering"). This command copies SwiftShader's two files (the driver and its ICD
manifest) from Debian's or Ubuntu's chromium-common package into the user's cache, where
`cfvs_maniskill` finds it by itself. It lives outside the package because importing the
package without a renderer is an error that names this command.
"""

from __future__ import annotations

import glob
import os
import shutil
import subprocess
import sys
import tempfile
from dataclasses import dataclass
from pathlib import Path

import tyro

ICD = "vk_swiftshader_icd.json"
LIBRARY = "libvk_swiftshader.so"
CHROMIUM_DIR = Path("/usr/lib/chromium")
"""Where Debian's chromium-common package installs SwiftShader."""


def default_dest() -> Path:
    """The user cache the package looks in (rendering/device.py)."""
    cache = os.environ.get("CFVS_CACHE") or Path.home() / ".cache" / "cfvs_maniskill"
    return Path(cache) / "swiftshader"


@dataclass
class SetupRenderArgs:
    """Put SwiftShader (a CPU Vulkan driver) where cfvs_maniskill finds it, unless a GPU is
    present. Needs Debian or Ubuntu (apt-get); run as root if the package lists are empty."""

    dest: Path | None = None
    """Folder for the driver; default $CFVS_CACHE/swiftshader (~/.cache/cfvs_maniskill/
    swiftshader). The package also finds it in <env>/share/cfvs_maniskill/swiftshader."""
    source: Path | None = None
    """A folder holding libvk_swiftshader.so and vk_swiftshader_icd.json to copy from (e.g.
    another machine's, for an install without apt); default: an installed chromium, else
    Debian's chromium-common package via apt-get."""
    force: bool = False
    """Copy it again even if the folder has it, and also on a machine with a GPU."""


class SetupError(RuntimeError):
    """SwiftShader could not be set up; the message says what to do instead."""


def _has_gpu_node() -> bool:
    # rendering/device.py has the same test, but importing it would import the package.
    return bool(glob.glob("/dev/nvidia[0-9]*") or glob.glob("/dev/dri/renderD*"))


def _from_deb(work: Path) -> Path:
    """Download chromium-common with apt-get and unpack it into `work`; its chromium dir."""
    if shutil.which("apt-get") is None or shutil.which("dpkg") is None:
        raise SetupError(
            "apt-get / dpkg not found: this is not Debian or Ubuntu. Install a package of "
            f"Chromium that ships {LIBRARY} and set CFVS_SWIFTSHADER_ICD to its {ICD}, or "
            "render on a GPU"
        )

    def download() -> subprocess.CompletedProcess:
        return subprocess.run(
            ["apt-get", "download", "-qq", "chromium-common"],
            cwd=work,
            capture_output=True,
            text=True,
        )

    got = download()
    if got.returncode != 0 and os.geteuid() == 0:  # empty package lists on a fresh machine
        subprocess.run(["apt-get", "update", "-qq"], capture_output=True, check=False)
        got = download()
    if got.returncode != 0:
        raise SetupError(
            f"`apt-get download chromium-common` failed ({got.stderr.strip() or got.stdout}); "
            "run `apt-get update` as root first, or install chromium"
        )
    deb = next(work.glob("chromium-common_*.deb"))
    subprocess.run(["dpkg", "-x", str(deb), str(work / "x")], check=True, capture_output=True)
    return work / "x" / CHROMIUM_DIR.relative_to("/")


def setup_render(args: SetupRenderArgs) -> str:
    """Install SwiftShader into `args.dest`; a line saying what was done."""
    dest = args.dest or default_dest()
    if _has_gpu_node() and not args.force:
        return "GPU render node found: SwiftShader is not needed (--force to install it)"
    if (dest / ICD).is_file() and (dest / LIBRARY).is_file() and not args.force:
        return f"SwiftShader is already in {dest}"
    with tempfile.TemporaryDirectory() as tmp:
        if args.source is not None:
            missing = [n for n in (LIBRARY, ICD) if not (args.source / n).is_file()]
            if missing:
                raise SetupError(f"--source {args.source}: no {' or '.join(missing)} in it")
            source, how = args.source, str(args.source)
        elif (CHROMIUM_DIR / LIBRARY).is_file() and (CHROMIUM_DIR / ICD).is_file():
            source, how = CHROMIUM_DIR, "the installed chromium"
        else:
            source, how = _from_deb(Path(tmp)), "Debian's chromium-common package"
        dest.mkdir(parents=True, exist_ok=True)
        for name in (LIBRARY, ICD):  # the manifest names the library beside it
            shutil.copy2(source / name, dest / name)
    return f"SwiftShader copied from {how} into {dest}"


def main(argv: list[str] | None = None) -> int:
    args = tyro.extras.subcommand_cli_from_dict(
        {"setup-render": SetupRenderArgs},
        args=argv,
        prog="cfvs-maniskill",
        description="Set-up commands of cfvs_maniskill (the others: python -m cfvs_maniskill.run, "
        ".eval, .report, .assets, .data, .train).",
    )
    try:
        print(setup_render(args))
    except (SetupError, OSError, subprocess.CalledProcessError) as e:
        print(f"error: cannot set up SwiftShader: {e}", file=sys.stderr)
        return 2
    return 0


if __name__ == "__main__":
    sys.exit(main())
