"""Episode videos for people: a lit close view of the hole and peg, an overview of the arm
and the wrist camera's own picture with the agent's estimated hole frame drawn into it,
over a caption per frame (agent, phase, contact force, time, outcome).

The film only looks: it renders the env's render cameras (`envs/peg_insert.py`: the close
view follows the hole) and the wrist camera, and reads true poses and the true contact
wrench for display. It never draws from the sensing model's random streams (no
`get_obs`, no `wrist_wrench`), so an episode filmed is the episode that was scored.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from PIL import Image, ImageDraw, ImageFont

from cfvs_maniskill.rendering.views import CLOSEUP_CAMERA, CLOSEUP_PX, OVERVIEW_CAMERA
from cfvs_maniskill.robots.ur5 import CAMERA_UID

CAPTION_PX = 64
AXIS_LENGTH = 0.03
"""Drawn hole frames: 3 cm axes (x red, y green, z blue, z out of the hole)."""
ESTIMATE_COLOUR = (255, 0, 200)
TRUE_COLOUR = (0, 200, 60)


@dataclass
class FilmConfig:
    every: int = 2
    """Film every n-th control step (20 Hz control: 2 -> a frame per 0.1 s of robot time)."""
    fps: int = 10
    """Playback rate: with every=2, the robot's own speed."""
    hold_s: float = 1.5
    """The last frame, with the outcome, is held this long."""


def project(points: np.ndarray, params: dict) -> np.ndarray:
    """World points (n, 3) -> pixel coordinates (n, 2) (nan behind the camera), with
    ManiSkill's OpenCV-convention camera parameters."""
    ext = np.asarray(params["extrinsic_cv"]).reshape(3, 4)
    K = np.asarray(params["intrinsic_cv"]).reshape(3, 3)
    p = points @ ext[:, :3].T + ext[:, 3]
    uv = p @ K.T
    with np.errstate(divide="ignore", invalid="ignore"):
        out = uv[:, :2] / uv[:, 2:3]
    out[p[:, 2] <= 1e-4] = np.nan
    return out


def draw_frame(img: Image.Image, H: np.ndarray, params: dict, colour, scale: float) -> None:
    """A hole frame (4x4, world) as a centre dot and three axes; `scale` maps the camera's
    pixels to the image's."""
    pts = H[:3, 3] + np.vstack([np.zeros(3), AXIS_LENGTH * H[:3, :3].T])
    uv = project(pts, params) * scale
    if not np.all(np.isfinite(uv)):
        return
    d = ImageDraw.Draw(img)
    axis_colours = [(230, 40, 40), (40, 200, 40), (40, 90, 255)]
    for k in range(3):
        d.line([tuple(uv[0]), tuple(uv[k + 1])], fill=axis_colours[k], width=3)
    r = 5
    x, y = uv[0]
    d.ellipse([x - r, y - r, x + r, y + r], outline=colour, width=3)


def _params(cam) -> dict:
    return {k: v[0].cpu().numpy() for k, v in cam.get_params().items()}


class Film:
    """Collects the frames of one episode at a time (`start` ... `finish`, driven by
    `episode.run_episode`); `write` saves them as an mp4."""

    def __init__(self, env, label: str, cfg: FilmConfig | None = None):
        self.env = env.unwrapped
        missing = {CLOSEUP_CAMERA, OVERVIEW_CAMERA} - set(self.env.scene.human_render_cameras)
        if missing:
            raise ValueError(
                f"videos need the env's render cameras {sorted(missing)}; this env has "
                f"{sorted(self.env.scene.human_render_cameras)} (human_render_camera_configs "
                "replaced them?)"
            )
        self.label = label
        self.cfg = cfg or FilmConfig()
        self.frames: list[np.ndarray] = []
        self.captions: list[str] = []
        """Each filmed frame's second caption line (phase or outcome)."""
        self.phase = ""
        self.estimate: np.ndarray | None = None
        self._steps = 0
        self.render_s = 0.0
        """Wall time spent rendering and composing frames (the video's cost)."""
        self._font = ImageFont.load_default(size=20)
        self._small = ImageFont.load_default(size=16)

    def start(self) -> None:
        self.frames, self.captions = [], []
        self.phase, self.estimate, self._steps = "", None, 0
        self.render_s = 0.0

    def note(self, phase: str, estimate: np.ndarray | None = None) -> None:
        """What the next frames' caption says, and the agent's hole estimate to draw."""
        self.phase = phase
        if estimate is not None:
            self.estimate = np.asarray(estimate, np.float64)

    def on_step(self, executor) -> None:
        """The executor's per-control-step hook (its own phase names the insertion's)."""
        self._steps += 1
        if self._steps % self.cfg.every == 0:
            self.capture(executor.servo_time, phase=executor.phase or self.phase)

    def capture(self, t: float, phase: str = "", outcome: str = "") -> None:
        t0 = time.perf_counter()
        self.captions.append(outcome or phase or self.phase)
        self.frames.append(self._compose(t, self.captions[-1], bool(outcome)))
        self.render_s += time.perf_counter() - t0

    def finish(self, t: float, outcome: str) -> None:
        """The last frame, captioned with the outcome ("success" or "failure: why")."""
        self.capture(t, outcome=outcome)
        self.frames.extend([self.frames[-1]] * int(self.cfg.hold_s * self.cfg.fps))

    def write(self, path: Path) -> Path:
        """The frames so far as an mp4 at `path`."""
        import imageio.v2 as imageio

        t0 = time.perf_counter()
        path.parent.mkdir(parents=True, exist_ok=True)
        with imageio.get_writer(
            path, fps=self.cfg.fps, codec="libx264", quality=7, macro_block_size=8
        ) as w:
            for f in self.frames:
                w.append_data(f)
        self.render_s += time.perf_counter() - t0
        return path

    # ------------------------------------------------------------------ one frame
    def _compose(self, t: float, line2: str, is_outcome: bool) -> np.ndarray:
        u = self.env
        u.scene.update_render(update_sensors=True, update_human_render_cameras=True)
        cams = u.scene.human_render_cameras
        big = CLOSEUP_PX
        small = big // 2
        canvas = Image.new("RGB", (big + small, big + CAPTION_PX), (24, 26, 30))
        close = self._picture(cams[CLOSEUP_CAMERA])
        draw_frame(close, u.hole_pose, _params(cams[CLOSEUP_CAMERA]), TRUE_COLOUR, 1.0)
        if self.estimate is not None:
            draw_frame(close, self.estimate, _params(cams[CLOSEUP_CAMERA]), ESTIMATE_COLOUR, 1.0)
        canvas.paste(close.resize((big, big)), (0, 0))
        canvas.paste(self._picture(cams[OVERVIEW_CAMERA]).resize((small, small)), (big, 0))
        wrist_cam = u.scene.sensors[CAMERA_UID]
        wrist = self._depth_picture(wrist_cam)
        scale = small / wrist.width
        wrist = wrist.resize((small, small), Image.Resampling.NEAREST)
        if self.estimate is not None:
            draw_frame(wrist, self.estimate, _params(wrist_cam), ESTIMATE_COLOUR, scale)
        canvas.paste(wrist, (big, small))
        d = ImageDraw.Draw(canvas)
        labels = [
            ((6, 6), "close view (green: true hole, magenta: agent's estimate)"),
            ((big + 6, 6), "overview"),
            ((big + 6, small + 6), "wrist camera depth (clean)"),
        ]
        for xy, text in labels:
            d.text(
                xy,
                text,
                fill=(255, 255, 255),
                font=self._small,
                stroke_width=2,
                stroke_fill=(0, 0, 0),
            )
        force = float(np.linalg.norm(u.contact_wrench()[0]))
        line1 = f"{self.label}   {u.task.name}   t = {t:5.2f} s   contact force {force:5.1f} N"
        colour = (255, 255, 255)
        if is_outcome:
            colour = (120, 230, 120) if line2.startswith("success") else (255, 120, 110)
        d.text((10, big + 6), line1, fill=(255, 255, 255), font=self._font)
        d.text((10, big + 34), line2, fill=colour, font=self._font)
        return np.asarray(canvas)

    @staticmethod
    def _picture(cam) -> Image.Image:
        cam.capture()
        rgb = cam.get_obs(rgb=True, depth=False, position=False, segmentation=False)["rgb"]
        return Image.fromarray(rgb[0].cpu().numpy()[..., :3].astype(np.uint8))

    @staticmethod
    def _depth_picture(cam) -> Image.Image:
        """The wrist camera's depth (what CFVS's cloud is made of), near = bright; the
        colour range follows the scene so the hole's edges stand out at any distance."""
        from matplotlib import colormaps

        cam.capture()
        obs = cam.get_obs(rgb=False, depth=True, position=False, segmentation=False)
        depth = obs["depth"][0, ..., 0].cpu().numpy().astype(np.float64)
        seen = depth > 0
        img = np.zeros((*depth.shape, 3), np.uint8)
        if seen.any():
            lo, hi = np.percentile(depth[seen], [2, 98])
            x = np.clip((depth - lo) / max(hi - lo, 1e-6), 0, 1)
            img[seen] = (255 * colormaps["magma"](1.0 - x[seen])[:, :3]).astype(np.uint8)
        return Image.fromarray(img)
