"""Synthetic pictures of the dissolution bench (paper section 4.2, Fig. 4b).

The scene, seen by the camera: an LED panel behind a diffuser fills the frame; its light profile is
symmetric about the image centre column (the panel is centred on the optical axis). A cylindrical glass
beaker stands left of centre, so the right half of the frame sees the panel only: that is where the
analysis finds the mirror image of its crop. Light through the water obeys Beer-Lambert per channel,

    I_c(row, col, t) = panel_c(row, col) * drift_c(t) * glass_c(row, col) * exp(-k_c * conc * path(col)),

with ``path`` the chord through the cylinder as a fraction of its diameter. The glass walls, the thick
base and the meniscus refract light away (dark bands); an object piece or air bubbles occasionally drift
through the crop. The linear image gets shot and read noise, then sRGB encoding, 8-bit quantisation
and, for :func:`render_jpeg`, JPEG compression.

Arrays are (row, col, channel) with channels in RGB order; linear values are in [0, 1].
"""
from __future__ import annotations

import functools
import math
from dataclasses import dataclass

import cv2
import numpy as np

from drivers.errors import DriverError

__all__ = ["BenchScene", "Intrusion", "SceneError", "render_linear", "render_frame", "render_jpeg", "srgb_encode"]


class SceneError(DriverError, ValueError):
    """A bench scene parameter is out of range; the message names it and the allowed range."""


def _check(name: str, value: float, lo: float, hi: float) -> None:
    if not (lo <= value <= hi):
        raise SceneError(f"BenchScene.{name}={value!r} is outside [{lo}, {hi}]")


@dataclass(frozen=True)
class BenchScene:
    """Everything that fixes how the bench looks; frozen, so renders are reproducible.

    Geometry is given as fractions of the image width (``*_w``) or height (``*_h``) so that the same scene
    renders at the reduced default size or at the Nikon D750's 6016 x 4016.

    Parameters
    ----------
    width, height : int
        Image size, px.
    panel_peak : float
        Linear panel brightness at the image centre, in (0, 1].
    panel_falloff : float
        Fractional brightness loss at the image corners (radial, quadratic, symmetric about the centre).
    panel_asymmetry : float
        Static left-right brightness gradient of the panel (fraction across the full width); it breaks
        the mirror symmetry a little, as a real panel does, and the calibration absorbs it.
    panel_texture : float
        Relative standard deviation of the diffuser's static fine texture.
    beaker_x_w, beaker_radius_w : float
        Beaker axis column and outer radius, fractions of the width.
    beaker_top_h, water_h, beaker_bottom_h : float
        Beaker rim, water surface and inner bottom rows, fractions of the height.
    wall_w : float
        Thickness of the dark refracting wall band, fraction of the width.
    glass_transmittance : float
        Transmittance of the two glass walls in the clear part of the beaker.
    absorption_per_g_per_kg : tuple of 3 float
        Optical depth per g/kg along the beaker diameter, per channel (R, G, B).
    shot_noise, read_noise : float
        Sensor noise: sigma**2 = shot_noise**2 * I + read_noise**2 (linear units).
    brightness : float
        Overall light level of the day (panel setting, camera warm-up state).
    drift_amplitude : float
        Relative amplitude of the slow light drift.
    drift_period_s : float
        Period of the drift, s.
    intrusion_probability : float
        Probability that a frame shows an object piece or bubbles in or near the crop.
    seed : int
        Seed of the static diffuser texture.
    water_g : float
        Water mass in the beaker, g: recorded with the scene (a fixture's ``truth.json``), not used to render.
        The bench application's default is ``labapp.acquisition.settings.WATER`` (the same 500 g; its
        simulated bench passes it explicitly).
    """

    width: int = 1200
    height: int = 800
    panel_peak: float = 0.78
    panel_falloff: float = 0.30
    panel_asymmetry: float = 0.01
    panel_texture: float = 0.004
    beaker_x_w: float = 0.30
    beaker_radius_w: float = 0.19
    beaker_top_h: float = 0.14
    water_h: float = 0.30
    beaker_bottom_h: float = 0.90
    wall_w: float = 0.008
    glass_transmittance: float = 0.92
    absorption_per_g_per_kg: tuple[float, float, float] = (0.30, 0.20, 0.09)
    shot_noise: float = 0.012
    read_noise: float = 0.002
    brightness: float = 1.0
    drift_amplitude: float = 0.03
    drift_period_s: float = 2400.0
    intrusion_probability: float = 0.1
    seed: int = 0
    water_g: float = 500.0

    def __post_init__(self) -> None:
        if not (16 <= self.width <= 20000 and 16 <= self.height <= 20000):
            raise SceneError(f"BenchScene size {self.width}x{self.height} px is outside 16..20000 px")
        _check("panel_peak", self.panel_peak, 1e-3, 1.0)
        _check("panel_falloff", self.panel_falloff, 0.0, 0.9)
        _check("panel_asymmetry", self.panel_asymmetry, -0.2, 0.2)
        _check("panel_texture", self.panel_texture, 0.0, 0.1)
        _check("beaker_radius_w", self.beaker_radius_w, 0.02, 0.25)
        left, right = self.beaker_x_w - self.beaker_radius_w, self.beaker_x_w + self.beaker_radius_w
        if not (0.0 < left and right < 0.5):
            raise SceneError(f"beaker spans columns {left:.3f}..{right:.3f} of the width; it must lie inside "
                             "(0, 0.5) so the right half of the image sees the panel only")
        if not (0.0 <= self.beaker_top_h < self.water_h < self.beaker_bottom_h <= 1.0):
            raise SceneError(f"need 0 <= beaker_top_h < water_h < beaker_bottom_h <= 1, got "
                             f"{self.beaker_top_h}, {self.water_h}, {self.beaker_bottom_h}")
        _check("wall_w", self.wall_w, 0.0, 0.05)
        _check("glass_transmittance", self.glass_transmittance, 0.1, 1.0)
        if len(self.absorption_per_g_per_kg) != 3 or min(self.absorption_per_g_per_kg) < 0:
            raise SceneError(f"absorption_per_g_per_kg={self.absorption_per_g_per_kg!r} must be 3 values >= 0")
        _check("shot_noise", self.shot_noise, 0.0, 0.2)
        _check("read_noise", self.read_noise, 0.0, 0.2)
        _check("brightness", self.brightness, 0.1, 1.5)
        _check("drift_amplitude", self.drift_amplitude, 0.0, 0.5)
        _check("drift_period_s", self.drift_period_s, 1.0, 1e7)
        _check("intrusion_probability", self.intrusion_probability, 0.0, 1.0)
        _check("water_g", self.water_g, 1.0, 1e5)

    def default_crop(self) -> tuple[int, int, int]:
        """A square crop well inside the water: (x, y, size) in px, size a multiple of 40."""
        size = max(40, int(0.17 * self.width) // 40 * 40)
        water_rows = (self.water_h + 0.05) * self.height, (self.beaker_bottom_h - 0.05) * self.height
        size = min(size, int(water_rows[1] - water_rows[0]) // 40 * 40)
        x = round(self.beaker_x_w * self.width - size / 2)
        y = round(0.5 * (water_rows[0] + water_rows[1]) - size / 2)
        return x, y, size

    def drift(self, t_s: float) -> np.ndarray:
        """Light level multiplier per channel at time ``t_s`` (s); (3,) ndarray."""
        phase = 2.0 * math.pi * t_s / self.drift_period_s + np.array([0.0, 0.4, 0.8])
        return self.brightness * (1.0 + self.drift_amplitude * np.sin(phase))


@dataclass(frozen=True)
class Intrusion:
    """Something in the light path besides the solution: ``kind`` is "object" or "bubble"; px."""

    kind: str
    row: float
    col: float
    radius: float


@functools.lru_cache(maxsize=2)
def _static_layers(scene: BenchScene) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Panel light (H, W, 3), glass transmission (H, W, 3) and chord fraction (H, W), all float32."""
    h, w = scene.height, scene.width
    rows = np.arange(h, dtype=np.float32)[:, None]
    cols = np.arange(w, dtype=np.float32)[None, :]
    u = (cols - (w - 1) / 2) / (w / 2)
    v = (rows - (h - 1) / 2) / (h / 2)
    profile = 1.0 - scene.panel_falloff * 0.5 * (u * u + v * v) + 0.5 * scene.panel_asymmetry * u
    texture = cv2.GaussianBlur(np.random.default_rng(scene.seed).standard_normal((h, w)).astype(np.float32),
                               (0, 0), max(1.0, w / 600))
    texture *= scene.panel_texture / max(float(texture.std()), 1e-12)
    panel = (scene.panel_peak * profile * (1.0 + texture))[..., None] * np.array([1.0, 0.97, 0.93], np.float32)

    xc, radius = scene.beaker_x_w * w, scene.beaker_radius_w * w
    wall = max(1.0, scene.wall_w * w)
    dx = np.abs(cols - xc)
    inside = dx < radius - wall
    top, bottom = scene.beaker_top_h * h, scene.beaker_bottom_h * h
    base = max(2.0, 0.02 * h)
    # Meniscus: the surface climbs the wall over a few mm and refracts light away in a dark band.
    surface = scene.water_h * h - 0.012 * h * np.exp(-(radius - wall - dx) / (0.015 * w))
    band = max(1.5, 0.006 * h)
    glass = np.ones((h, w), np.float32)
    in_beaker = (rows >= top) & (rows < bottom + base) & (dx < radius)
    glass[in_beaker] = scene.glass_transmittance
    glass[(rows >= top) & (rows < bottom + base) & (dx >= radius - wall) & (dx < radius)] = 0.25
    glass[(rows >= bottom) & (rows < bottom + base) & (dx < radius)] = 0.45
    meniscus = np.exp(-0.5 * ((rows - surface) / band) ** 2)
    glass *= np.where(inside, 1.0 - 0.7 * meniscus, 1.0).astype(np.float32)
    hotplate = (rows >= bottom + base) & (dx < 1.15 * radius)
    glass[hotplate] = 0.03
    water = inside & (rows > surface) & (rows < bottom)
    chord = np.where(water, np.sqrt(np.clip(1.0 - (dx / (radius - wall)) ** 2, 0.0, 1.0)), 0.0).astype(np.float32)
    glass3 = glass[..., None] * np.where(in_beaker[..., None], np.array([1.0, 1.0, 0.98], np.float32), 1.0)
    return panel.astype(np.float32), glass3.astype(np.float32), chord


def _draw_intrusions(scene: BenchScene, rng: np.random.Generator) -> tuple[Intrusion, ...]:
    if rng.random() >= scene.intrusion_probability:
        return ()
    x, y, size = scene.default_crop()
    margin = 0.2 * size
    def centre() -> tuple[float, float]:
        return float(rng.uniform(y - margin, y + size + margin)), float(rng.uniform(x - margin, x + size + margin))
    if rng.random() < 0.4:
        return (Intrusion("object", *centre(), float(rng.uniform(0.02, 0.05) * scene.width)),)
    return tuple(Intrusion("bubble", *centre(), float(rng.uniform(0.004, 0.012) * scene.width))
                 for _ in range(int(rng.integers(1, 5))))


def _apply_intrusions(image: np.ndarray, intrusions: tuple[Intrusion, ...]) -> None:
    h, w = image.shape[:2]
    for item in intrusions:
        r0, r1 = max(0, int(item.row - item.radius) - 1), min(h, int(item.row + item.radius) + 2)
        c0, c1 = max(0, int(item.col - item.radius) - 1), min(w, int(item.col + item.radius) + 2)
        if r0 >= r1 or c0 >= c1:
            continue
        rr, cc = np.mgrid[r0:r1, c0:c1]
        dist = np.hypot(rr - item.row, cc - item.col) / item.radius
        if item.kind == "object":
            factor = np.where(dist < 1.0, 0.12, 1.0)[..., None] * np.array([0.6, 0.8, 1.0])
        else:  # a bubble: clear core, dark refracting rim
            factor = np.where(dist < 0.65, 1.05, np.where(dist < 1.0, 0.35, 1.0))[..., None] * np.ones(3)
        image[r0:r1, c0:c1] *= factor.astype(np.float32)


def render_linear(scene: BenchScene, conc_g_per_kg: float, t_s: float,
                  rng: np.random.Generator) -> tuple[np.ndarray, tuple[Intrusion, ...]]:
    """The noisy linear image and the intrusions drawn into it.

    Parameters
    ----------
    scene : BenchScene
    conc_g_per_kg : float
        Concentration of the homogeneous solution, g/kg (>= 0).
    t_s : float
        Time, s; sets the light drift.
    rng : numpy.random.Generator
        Source of noise and intrusions.

    Returns
    -------
    image : (H, W, 3) ndarray of float32, linear in [0, 1], RGB
    intrusions : tuple of Intrusion
    """
    if not (conc_g_per_kg >= 0.0 and math.isfinite(conc_g_per_kg)):
        raise SceneError(f"conc_g_per_kg={conc_g_per_kg!r} must be a finite value >= 0")
    panel, glass, chord = _static_layers(scene)
    k = np.asarray(scene.absorption_per_g_per_kg, np.float32)
    image = panel * glass * scene.drift(t_s).astype(np.float32)
    image *= np.exp(-(conc_g_per_kg * chord)[..., None] * k)
    intrusions = _draw_intrusions(scene, rng)
    _apply_intrusions(image, intrusions)
    sigma = np.sqrt(scene.shot_noise ** 2 * image + scene.read_noise ** 2)
    image += sigma * rng.standard_normal(image.shape, dtype=np.float32)
    np.clip(image, 0.0, 1.0, out=image)
    return image, intrusions


def srgb_encode(linear: np.ndarray) -> np.ndarray:
    """Linear [0, 1] values to 8-bit sRGB (IEC 61966-2-1 transfer curve); same shape, uint8."""
    x = np.clip(linear, 0.0, 1.0)
    encoded = np.where(x <= 0.0031308, 12.92 * x, 1.055 * np.power(x, 1.0 / 2.4) - 0.055)
    return np.round(encoded * 255.0).astype(np.uint8)


def render_frame(scene: BenchScene, conc_g_per_kg: float, t_s: float, rng: np.random.Generator) -> np.ndarray:
    """One camera frame of the bench at concentration ``conc_g_per_kg`` (g/kg) and time ``t_s`` (s).

    Returns
    -------
    (H, W, 3) ndarray of uint8, sRGB-encoded, RGB order
    """
    return srgb_encode(render_linear(scene, conc_g_per_kg, t_s, rng)[0])


def render_jpeg(scene: BenchScene, conc_g_per_kg: float, t_s: float, rng: np.random.Generator,
                quality: int = 92) -> bytes:
    """:func:`render_frame` compressed as a baseline JPEG of the given quality (1..100)."""
    if not 1 <= quality <= 100:
        raise SceneError(f"JPEG quality={quality!r} is outside 1..100")
    rgb = render_frame(scene, conc_g_per_kg, t_s, rng)
    ok, buf = cv2.imencode(".jpg", rgb[..., ::-1], [cv2.IMWRITE_JPEG_QUALITY, int(quality)])
    if not ok:
        raise SceneError("OpenCV could not encode the frame as JPEG")
    return buf.tobytes()
