"""The desktop studio (PySide6 + pyvistaqt). Imports corrlib; corrlib never imports it."""
