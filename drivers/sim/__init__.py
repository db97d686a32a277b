"""Device emulators and the synthetic bench renderer."""
from drivers.sim.bench_scene import BenchScene, Intrusion, SceneError, render_frame, render_jpeg, render_linear

__all__ = ["BenchScene", "Intrusion", "SceneError", "render_frame", "render_jpeg", "render_linear"]
