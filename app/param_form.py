"""A parameter form generated from a method's parameter dataclass (labels, bounds, help as tooltips)."""

from __future__ import annotations

import dataclasses
import math

from PySide6.QtWidgets import (
    QCheckBox,
    QComboBox,
    QDoubleSpinBox,
    QFormLayout,
    QLabel,
    QLineEdit,
    QPushButton,
    QSpinBox,
    QVBoxLayout,
    QWidget,
)

from corrlib.errors import ParameterError
from corrlib.methods.base import make_params, param_fields

SPINBOX_INT_MAX = 2**31 - 1  # QSpinBox holds a 32-bit int: unbounded int parameters stop here
SPINBOX_FLOAT_MAX = 1e12  # the range of an unbounded float parameter is +- this
SMALL_FLOAT = 1e-2  # float defaults below this (and not 0) get more decimals
DECIMALS_SMALL, DECIMALS = 8, 4
DEFAULT_FLOAT_STEP = 0.1  # single step of a float parameter whose default is 0


class ParamForm(QWidget):
    """Widgets for every field of a parameter dataclass; :meth:`params` validates and builds it."""

    def __init__(self, params_cls, parent=None):
        super().__init__(parent)
        self.params_cls = params_cls
        self.widgets: dict[str, QWidget] = {}
        layout = QVBoxLayout(self)
        form = QFormLayout()
        layout.addLayout(form)
        for f in param_fields(params_cls):
            widget = self._make_widget(f)
            widget.setToolTip(f.metadata.get("help", ""))
            label = QLabel(f.metadata.get("label", f.name))
            label.setToolTip(f.metadata.get("help", ""))
            form.addRow(label, widget)
            self.widgets[f.name] = widget
        self.error = QLabel("")
        self.error.setStyleSheet("color: #b00020")
        self.error.setWordWrap(True)
        layout.addWidget(self.error)
        reset = QPushButton("Reset to defaults")
        reset.clicked.connect(self.reset)
        layout.addWidget(reset)
        layout.addStretch(1)

    def _make_widget(self, f: dataclasses.Field) -> QWidget:
        meta = f.metadata
        default = f.default
        if meta.get("choices"):
            w = QComboBox()
            w.addItems([str(c) for c in meta["choices"]])
            w.setCurrentText(str(default))
            w.currentTextChanged.connect(self.validate)
            return w
        if isinstance(default, bool):
            w = QCheckBox()
            w.setChecked(default)
            return w
        if isinstance(default, int):
            w = QSpinBox()
            w.setRange(int(meta.get("low") if meta.get("low") is not None else -SPINBOX_INT_MAX),
                       int(min(meta.get("high") if meta.get("high") is not None else SPINBOX_INT_MAX,
                               SPINBOX_INT_MAX)))
            w.setValue(default)
            return w
        if isinstance(default, float):
            w = QDoubleSpinBox()
            low = meta.get("low")  # a small default or a small lower bound: enough decimals to type it
            small = (default != 0 and abs(default) < SMALL_FLOAT) or (low is not None and 0 < low < SMALL_FLOAT)
            w.setDecimals(DECIMALS_SMALL if small else DECIMALS)
            w.setRange(meta.get("low") if meta.get("low") is not None else -SPINBOX_FLOAT_MAX,
                       meta.get("high") if meta.get("high") is not None else SPINBOX_FLOAT_MAX)
            w.setSingleStep(10 ** math.floor(math.log10(abs(default))) if default else DEFAULT_FLOAT_STEP)
            w.setValue(default)
            return w
        w = QLineEdit(str(default))
        w.textChanged.connect(self.validate)
        return w

    def values(self) -> dict:
        out = {}
        for name, w in self.widgets.items():
            if isinstance(w, QComboBox):
                out[name] = w.currentText()
            elif isinstance(w, QCheckBox):
                out[name] = w.isChecked()
            elif isinstance(w, (QSpinBox, QDoubleSpinBox)):
                out[name] = w.value()
            else:
                out[name] = w.text()
        return out

    def set_values(self, values: dict) -> None:
        for name, value in values.items():
            w = self.widgets[name]
            if isinstance(w, QComboBox):
                w.setCurrentText(str(value))
            elif isinstance(w, QCheckBox):
                w.setChecked(bool(value))
            elif isinstance(w, (QSpinBox, QDoubleSpinBox)):
                w.setValue(value)
            else:
                w.setText(str(value))

    def reset(self) -> None:
        self.set_values({f.name: f.default for f in param_fields(self.params_cls)})
        self.validate()

    def validate(self, *_args) -> bool:
        try:
            make_params(self.params_cls, **self.values())
        except ParameterError as exc:
            self.error.setText(str(exc))
            return False
        self.error.setText("")
        return True

    def params(self):
        """The validated parameter instance; raises :class:`ParameterError` (also shown in the form)."""
        try:
            return make_params(self.params_cls, **self.values())
        except ParameterError as exc:
            self.error.setText(str(exc))
            raise
