"""Entry point of ``corr-studio``.

``corr-studio [--demo] [--method NAME] [--tab NAME] [--screenshot PATH] [FILES…]``

* ``--demo`` opens the bundled pair and runs the best available method;
* ``--screenshot PATH`` renders the window once the first result is shown
  (or after ``--timeout`` seconds), writes the PNG and exits — for
  documentation and for checking the GUI on a machine without a screen
  (run it under ``xvfb-run``); the errors the window shows go to stderr,
  and the exit status is 1 after one, or after the timeout.
"""

from __future__ import annotations

import argparse
import math
import os
import sys

from app.views import TAB_NAMES


DEFAULT_SCREENSHOT_TIMEOUT_S = 300.0
SCREENSHOT_SETTLE_MS = 500  # after the first result: let the views finish drawing before the grab
NO_JOB_SCREENSHOT_DELAY_MS = 1500  # with nothing to run, grab the window this long after start
SETTLE_EVENT_ROUNDS = 5  # event-loop passes that apply the requested tab/slider/function before the grab
NO_DISPLAY_HINT = ('xvfb-run -a -s "-screen 0 1600x1000x24" corr-studio --demo --screenshot shot.png')


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="corr-studio", description="Desktop studio for shape correspondence.")
    parser.add_argument("files", nargs="*", help="source and target (meshes, contours or silhouettes)")
    parser.add_argument("--demo", action="store_true", help="open the bundled demo pair and run a method")
    parser.add_argument("--method", help="method to run on start (default: the best available)")
    parser.add_argument("--tab", type=str.capitalize, choices=TAB_NAMES, help=f"tab to show: {', '.join(TAB_NAMES)}")
    from app.views.pair import MODES

    parser.add_argument("--pair-mode", choices=list(MODES),
                        help="what the pair view shows")
    parser.add_argument("--sequence-t", type=float, help="with --screenshot: put the sequence slider at this t")
    parser.add_argument("--sequence-motion", choices=["flow", "rigid", "linear"],
                        help="with --screenshot: the motion the sequence view shows (default: the method's own)")
    parser.add_argument("--torus-function", metavar="NAME",
                        help="with --screenshot: the product function the torus view shows (cost, density, "
                             "harmonic_1, ...)")
    parser.add_argument("--retrieve", metavar="FOLDER", help="rank this folder against the query (first file)")
    parser.add_argument("--compare", action="store_true", help="run the comparison of all methods on the pair")
    parser.add_argument("--screenshot", metavar="PATH", help="write a PNG of the window after the first result")
    parser.add_argument("--timeout", type=float, default=DEFAULT_SCREENSHOT_TIMEOUT_S,
                        help="--screenshot gives up after this many s")
    parser.add_argument("--param", action="append", metavar="NAME=VALUE", default=[],
                        help="parameter of the started method")
    parser.add_argument("--bench", action="store_true", help="run the studio benchmarks and exit")
    return parser


def has_display() -> bool:
    """False (after a message on stderr) when Qt's xcb platform has no X display to connect to."""
    os.environ.setdefault("QT_QPA_PLATFORM", "xcb")
    if os.environ["QT_QPA_PLATFORM"] == "xcb" and not os.environ.get("DISPLAY"):
        print("corr-studio: no display (DISPLAY is not set). Run it on a desktop, or on a virtual screen: "
              + NO_DISPLAY_HINT, file=sys.stderr)
        return False
    return True


def wait_for_loads(window) -> None:
    """Run the event loop until the files the window is loading (in its worker) are loaded or failed."""
    from PySide6.QtCore import QEventLoop

    loop = QEventLoop()
    window.loading_finished.connect(loop.quit)
    if window.is_loading():
        loop.exec()
    window.loading_finished.disconnect(loop.quit)


def open_inputs(window, args) -> None:
    """Load the files (first: source, second: target) and the demo pair; return when they are loaded."""
    for i, path in enumerate(args.files[:2]):
        window.load_file(path, "source" if i == 0 else "target")
    if args.demo:
        window.load_demo()
    wait_for_loads(window)


def select_tab(window, name: str | None) -> None:
    """Show the tab titled ``name`` (case-insensitive); nothing for None or an unknown name."""
    for i in range(window.tabs.count()):
        if name and window.tabs.tabText(i).lower() == name.lower():
            window.tabs.setCurrentIndex(i)


def apply_param(window, item: str, method: str | None) -> str | None:
    """Set ``NAME=VALUE`` in the form of ``method`` (default: the selected one); an error message or None."""
    from corrlib.errors import ParameterError
    from corrlib.methods.base import make_params

    name, _, value = item.partition("=")
    method = method or window.method_box.currentData()
    form = window.form_of(method) if method is not None else None
    if form is None:
        return f"--param {item}: no method to apply it to (load inputs or pass --method)"
    current = form.values()
    if name not in current:
        return f"--param {item}: {method} has no parameter {name!r} (it has {', '.join(current)})"
    try:  # the method's own checks (range, choices, true/false words), not the widget's silent clamping
        wanted = getattr(make_params(form.params_cls, **{name: value}), name)
    except ParameterError as exc:
        return f"--param {item}: {exc}"
    current[name] = wanted
    form.set_values(current)
    shown = form.values()[name]
    if shown != wanted and not (isinstance(wanted, float) and math.isclose(shown, wanted, rel_tol=1e-9)):
        return f"--param {item}: the form holds {shown!r}, not {wanted!r}"
    return None


def start_jobs(window, args) -> bool:
    """Start what the command line asks for (retrieval, comparison or one method); True if a job started."""
    if args.retrieve:
        window.retrieval_view.set_folder(args.retrieve)
        window.tabs.setCurrentWidget(window.retrieval_view)
        window.run_retrieval()
        return True
    if args.compare:
        window.tabs.setCurrentWidget(window.compare_view)
        window.run_compare()
        return True
    if (args.demo or args.method or len(args.files) >= 2) and window.method_box.count():
        window.run_method(method=args.method)
        return True
    return False


def schedule_screenshot(app, window, args, started: bool, errors: list) -> None:
    """Write ``args.screenshot`` after the first result or error (or soon, if nothing runs), then quit with
    exit status 1 if the window showed an error (``errors``: every message shown so far, and later) or no
    result came within ``args.timeout`` seconds, 0 otherwise."""
    from PySide6.QtCore import QTimer

    from app.views.sequence import STEPS

    def shoot(*_a):
        select_tab(window, args.tab)  # a finished job switches to its own view; show the requested one
        view = window.sequence_view
        if args.sequence_motion and not view.choose_motion(args.sequence_motion):
            print(f"corr-studio: the result offers no {args.sequence_motion} motion (it offers: "
                  f"{', '.join(view.options) or 'none'}); the screenshot shows the default", file=sys.stderr)
        if args.sequence_t is not None and view.positions is not None:
            view.slider.setValue(int(STEPS * args.sequence_t / view.t_max.value()))
        if args.torus_function:
            offered = [window.product_view.function.itemText(i) for i in range(window.product_view.function.count())]
            if args.torus_function in offered:
                window.product_view.function.setCurrentText(args.torus_function)
            else:
                print(f"corr-studio: the result offers no torus function {args.torus_function} (it offers: "
                      f"{', '.join(offered) or 'none'}); the screenshot shows the default", file=sys.stderr)
        while window.retrieval_view.draw_next_thumbnail():  # the gallery's thumbnails, all of them
            pass
        for _ in range(SETTLE_EVENT_ROUNDS):
            app.processEvents()
        QTimer.singleShot(SCREENSHOT_SETTLE_MS,
                          lambda: (window.save_screenshot(args.screenshot), window.close(), app.exit(1 if errors else 0)))

    if started:
        window.result_ready.connect(shoot)
        window.error_shown.connect(shoot)
    else:
        QTimer.singleShot(NO_JOB_SCREENSHOT_DELAY_MS, shoot)
    def give_up():
        print(f"corr-studio: no result within --timeout {args.timeout:g} s; the screenshot shows the window as it "
              "was", file=sys.stderr)
        window.save_screenshot(args.screenshot)
        app.exit(1)

    QTimer.singleShot(int(args.timeout * 1000), give_up)


def main(argv: list[str] | None = None) -> int:
    import time

    t_start = time.perf_counter()
    args = build_parser().parse_args(argv)
    if args.method is not None:
        from corrlib.errors import ParameterError
        from corrlib.methods.registry import get_method

        try:
            get_method(args.method)
        except ParameterError as exc:
            print(f"corr-studio: --method: {exc}", file=sys.stderr)
            return 2
    if not has_display():
        return 2
    if args.bench:
        from app.bench import run_benchmarks

        return run_benchmarks(t_start)
    from PySide6.QtWidgets import QApplication

    from app.main_window import MainWindow

    app = QApplication.instance() or QApplication(sys.argv[:1])
    window = MainWindow(interactive=args.screenshot is None)
    errors: list[str] = []
    window.error_shown.connect(errors.append)  # before the inputs load: a file that fails to is an error too
    if args.screenshot:  # no one reads the window's log: the errors go to stderr too
        window.error_shown.connect(lambda message: print(f"corr-studio: {message}", file=sys.stderr))
    window.show()
    open_inputs(window, args)
    select_tab(window, args.tab)
    if args.pair_mode:
        window.pair_view.mode.setCurrentText(args.pair_mode)
    for item in args.param:
        error = apply_param(window, item, args.method)
        if error is not None:
            print(f"corr-studio: {error}", file=sys.stderr)
            return 2
    errors_before = len(errors)
    # a job refused at once (an error while starting it) is not waited for
    started = start_jobs(window, args) and len(errors) == errors_before
    if args.screenshot:
        schedule_screenshot(app, window, args, started, errors)
    return app.exec()


if __name__ == "__main__":
    sys.exit(main())
