"""Sequence view: interpolation and extrapolation player with in-place vertex updates."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
from PySide6.QtCore import Qt, QTimer
from PySide6.QtWidgets import (
    QCheckBox,
    QComboBox,
    QDoubleSpinBox,
    QHBoxLayout,
    QLabel,
    QPushButton,
    QSlider,
    QVBoxLayout,
    QWidget,
)

from app.views.camera import FramedView, ShapeDisplay
from app.views.scene import LazyPlotter, add_caption, coordinate_colors, polydata
from corrlib.methods.divergence_free import SEQUENCE_T_MAX

STEPS = 1000  # slider positions from t = 0 to t max
DEFAULT_T_MAX = 1.5
T_MAX_STEP = 0.1
SPEED_RANGE = (0.05, 5.0)  # playback speed, t per second
DEFAULT_SPEED = 0.5
FRAME_INTERVAL_MS = 30  # playback timer period
PICTURE_STRIP_FRAMES = 6
#: what the tab says while it has no motion to show
SEQUENCE_HINT = ("Run a method on two meshes to see the source move to the target here (a match of contours has "
                 "no motion).")
#: the motion box's words for the kinds of :func:`app.jobs.sequence_options`
MOTION_NAMES = {"flow": "the method's flow", "rigid": "as rigid as possible", "linear": "linear"}


class SequenceView(QWidget, FramedView):
    """Slider over t in [0, t_max] (t > 1 extrapolates), play/pause, speed, loop, and the choice of motion
    where a result offers several (the method's flow, as rigid as possible, linear)."""

    def __init__(self, parent=None):
        super().__init__(parent)
        self.slider = QSlider(Qt.Horizontal)
        self.slider.setRange(0, STEPS)
        self.slider.valueChanged.connect(self._on_slider)
        self.t_max = QDoubleSpinBox()
        # up to the t a divergence-free result stores its flow to (app.jobs.sequence_of integrates that far)
        self.t_max.setRange(1.0, SEQUENCE_T_MAX)
        self.t_max.setSingleStep(T_MAX_STEP)
        self.t_max.setValue(DEFAULT_T_MAX)
        self.t_max.setToolTip("Largest t of the slider; t > 1 extrapolates beyond the target.")
        self.t_max.valueChanged.connect(self._on_t_max)
        self.speed = QDoubleSpinBox()
        self.speed.setRange(*SPEED_RANGE)
        self.speed.setValue(DEFAULT_SPEED)
        self.speed.setSuffix(" /s")
        self.loop = QCheckBox("loop")
        self.loop.setChecked(True)
        self.play_button = QPushButton("Play")
        self.play_button.clicked.connect(self.toggle_play)
        self.label = QLabel("t = 0.00")
        self.kind = QLabel("")
        self.kind.setWordWrap(True)  # a long description must not widen the window
        self.motion = QComboBox()
        self.motion.setSizeAdjustPolicy(QComboBox.AdjustToContents)  # the longest name whole
        self.motion.setToolTip("How the source moves to the target: the method's own deformation, or an "
                               "interpolation through its map. Export ▸ frames writes the motion shown.")
        self.motion.currentIndexChanged.connect(self._on_motion)
        self.timer = QTimer(self)
        self.timer.setInterval(FRAME_INTERVAL_MS)
        self.timer.timeout.connect(self._tick)
        row = QHBoxLayout()
        for w in (self.play_button, QLabel("t max"), self.t_max, QLabel("speed"), self.speed, self.loop,
                  self.label):
            row.addWidget(w)
        row.addWidget(self.slider, 1)
        layout = QVBoxLayout(self)
        top = QHBoxLayout()
        self.motion_label = QLabel("motion")
        top.addWidget(self.motion_label)
        top.addWidget(self.motion)
        top.addWidget(self.kind, 1)
        layout.addLayout(top)
        plot_box = QVBoxLayout()
        layout.addLayout(plot_box, 1)
        layout.addLayout(row)
        # no multisampling (and no timed auto-updates): scrubbing redraws once per slider step
        self._plotter = LazyPlotter(self, plot_box, multi_samples=1)
        self.mesh = None
        self.positions: Callable[[float], np.ndarray] | None = None
        self.source = None
        self.display: ShapeDisplay | None = None  # the source's display frame (every frame is drawn in it)
        self.description = ""
        self.caption = ""  # the source's name and the target's: what moves where
        #: the poses the camera is fitted to, in the display frame: the source, the target pose (t = 1) and the
        #: farthest extrapolated pose (t max)
        self.ends: list[np.ndarray] = []
        self.options: dict[str, tuple] = {}  # kind -> (positions, description) the motion box offers
        self._controls = (self.play_button, self.t_max, self.speed, self.loop, self.slider)
        self.clear()

    def view_plotter(self):
        return self._plotter.get() if self.mesh is not None else None

    def framed_points(self) -> list[np.ndarray]:
        return [] if self.mesh is None else self.ends

    def redraw(self) -> None:
        if self.source is not None and self.positions is not None:
            value = self.slider.value()
            self._show(self.source, self.positions, self.description)
            self.slider.setValue(value)

    @property
    def plotter(self):
        return self._plotter.get()

    def clear(self) -> None:
        """Forget the sequence (a new shape was loaded: the last pair's motion no longer fits it)."""
        self.source = self.positions = self.mesh = self.display = None
        self.ends, self.description, self.caption = [], "", ""
        if self.timer.isActive():
            self.toggle_play()  # stopped, the button saying Play again
        self.kind.setText(SEQUENCE_HINT)
        self._offer({})
        if self._plotter.created:
            self.plotter.clear_actors()

    def set_sequences(self, source, options: dict[str, tuple], target=None) -> None:
        """Show ``source`` moving along the first of ``options`` (kind -> ``(positions, description)``, see
        :func:`app.jobs.sequence_options`) towards ``target`` (named in the caption); the motion box offers all
        of them."""
        self._offer(options)
        self.caption = source.name if target is None else f"{source.name} to {target.name}"
        kind = next(iter(options))
        self._show(source, *options[kind])

    def _offer(self, options: dict[str, tuple]) -> None:
        self.options = dict(options)
        self.motion.blockSignals(True)  # filling the box is not a choice
        self.motion.clear()
        for kind in self.options:
            self.motion.addItem(MOTION_NAMES.get(kind, kind), kind)
        self.motion.blockSignals(False)
        self.motion.setEnabled(len(self.options) > 1)
        self.motion.setVisible(bool(self.options))  # an empty box floated above an empty view
        self.motion_label.setVisible(bool(self.options))
        for control in self._controls:  # nothing to play or scrub without a motion
            control.setEnabled(bool(self.options))

    def choose_motion(self, kind: str) -> bool:
        """Show the motion ``kind`` ("flow", "rigid", "linear"); False where the result does not offer it."""
        index = self.motion.findData(kind)
        if index < 0:
            return False
        self.motion.setCurrentIndex(index)
        return True

    def _on_motion(self, index: int) -> None:
        """Another motion of the same result: the slider and the camera stay where they are."""
        kind = self.motion.itemData(index)
        if kind not in self.options or self.source is None:
            return
        self.positions, self.description = self.options[kind]
        self.kind.setText(self.description)
        self._on_slider(self.slider.value())

    def _show(self, source, positions: Callable[[float], np.ndarray], description: str) -> None:
        """Draw ``source`` anew, deforming along ``positions(t)`` (:func:`corrlib.morph.sequence_positions`)."""
        self.source = source
        self.positions = positions
        self.description = description
        self.kind.setText(description)
        self.plotter.clear_actors()
        self.display = ShapeDisplay.of(source.vertices, self.up)
        self.mesh = polydata(self.display.points(source.vertices), source.faces)
        self.plotter.add_mesh(self.mesh, scalars=coordinate_colors(source.vertices), rgb=True)
        add_caption(self.plotter, self.caption or source.name)
        self.ends = self._framed_poses()
        self.fit_preset()
        self.slider.setValue(0)
        self._on_slider(0)

    def _framed_poses(self) -> list[np.ndarray]:
        """The poses at t = 0, 1 and t max in the display frame: fitted to them, the camera keeps the whole motion,
        the extrapolated part too, in view."""
        times = (0.0, 1.0) + ((self.t_max.value(),) if self.t_max.value() > 1.0 else ())
        return [self.display.points(self.positions(t)) for t in times]

    def _on_t_max(self, _value: float) -> None:
        """A new slider range: the frame at the slider's position, and the camera refitted (while at its preset)
        to the farthest pose."""
        if self.mesh is None or self.positions is None:
            return
        self.ends = self._framed_poses()
        self._on_resized()
        self._on_slider(self.slider.value())

    def t(self) -> float:
        return self.slider.value() / STEPS * self.t_max.value()

    def _on_slider(self, _value: int) -> None:
        t = self.t()
        self.label.setText(f"t = {t:.2f}")
        if self.mesh is None or self.positions is None:
            return
        self.mesh.points[:] = self.display.points(self.positions(t))  # in place: no new VTK objects while scrubbing
        self.mesh.Modified()
        self.plotter.update()  # one repaint, scheduled by Qt (render() would draw twice)

    def toggle_play(self) -> None:
        if self.timer.isActive():
            self.timer.stop()
            self.play_button.setText("Play")
        else:
            self.timer.start()
            self.play_button.setText("Pause")

    def _tick(self) -> None:
        step = int(round(self.speed.value() * STEPS * self.timer.interval() / 1000.0 / self.t_max.value()))
        value = self.slider.value() + max(step, 1)
        if value > STEPS:
            if not self.loop.isChecked():
                self.toggle_play()
                return
            value = 0
        self.slider.setValue(value)

    def frames(self, count: int, t_max: float | None = None):
        """(t, vertices) of ``count`` evenly spaced frames from 0 to ``t_max``, with t = 1 (the target) among them
        (:func:`corrlib.morph.frame_times`)."""
        from corrlib.morph import frame_times

        t_max = self.t_max.value() if t_max is None else t_max
        for t in frame_times(count, t_max):
            yield float(t), self.positions(float(t))

    def picture_strip(self, count: int = PICTURE_STRIP_FRAMES) -> np.ndarray:
        """(h, count * w, 3) uint8: screenshots of the view at evenly spaced t, side by side."""
        current = self.slider.value()
        images = []
        for i in range(count):
            self.slider.setValue(int(round(i * STEPS / max(count - 1, 1))))
            self.plotter.render()
            images.append(self.plotter.screenshot(return_img=True))
        self.slider.setValue(current)
        return np.hstack(images)

    def close_plotters(self) -> None:
        self.timer.stop()
        self._plotter.close()
