"""Panel "Smooth": implicit Laplacian / mean-curvature smoothing of the vertex positions."""

from __future__ import annotations

from algorithms.smoothing import SmoothParams
from app.recipes.smooth import change_advice, smooth_steps
from app.panels.base import MethodPanel


class SmoothPanel(MethodPanel):
    title = "Smooth"
    description = ("Smooths the shape with implicit steps (direct sparse solver). Try 10 steps "
                   "first, then raise the step size for a stronger effect.")
    params_cls = SmoothParams
    plot_metrics = ("bending_energy",)
    plot_title = "Bending energy ∫H² dA"

    def build_steps(self, state, params):
        return smooth_steps(state, params)

    def _on_finished(self, step) -> None:
        super()._on_finished(step)
        if self.window_.last_job_name != self.title:
            return
        params = (self.last_request or {}).get("params") or self.form.params()
        advice = change_advice(step, params)
        if advice:
            self.status_label.setText(f"{self.status_label.text()} {advice}")
