"""Entry point of ``corr-studio``.

``corr-studio [--demo] [--method NAME] [--tab NAME] [--screenshot PATH] [FILES…]``

* ``--demo`` opens the bundled pair and runs the best available method;
* ``--screenshot PATH`` renders the window once the first result is shown
  (or after ``--timeout`` seconds), writes the PNG and exits — for
  documentation and for checking the GUI on a machine without a screen
  (run it under ``xvfb-run``).
"""

from __future__ import annotations

import argparse
import os
import sys


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="corr-studio", description="Desktop studio for shape correspondence.")
    parser.add_argument("files", nargs="*", help="source and target (meshes, contours or silhouettes)")
    parser.add_argument("--demo", action="store_true", help="open the bundled demo pair and run a method")
    parser.add_argument("--method", help="method to run on start (default: the best available)")
    parser.add_argument("--tab", help="tab to show: Pair, Product, Sequence, Retrieval, Compare")
    from app.views.pair import MODES

    parser.add_argument("--pair-mode", choices=list(MODES),
                        help="what the pair view shows")
    parser.add_argument("--sequence-t", type=float, help="with --screenshot: put the sequence slider at this t")
    parser.add_argument("--torus-function", metavar="NAME",
                        help="with --screenshot: the product function the torus view shows (cost, density, "
                             "harmonic_1, ...)")
    parser.add_argument("--retrieve", metavar="FOLDER", help="rank this folder against the query (first file)")
    parser.add_argument("--compare", action="store_true", help="run the comparison of all methods on the pair")
    parser.add_argument("--screenshot", metavar="PATH", help="write a PNG of the window after the first result")
    parser.add_argument("--timeout", type=float, default=300.0, help="--screenshot gives up after this many s")
    parser.add_argument("--param", action="append", metavar="NAME=VALUE", default=[],
                        help="parameter of the started method")
    parser.add_argument("--bench", action="store_true", help="run the studio benchmarks and exit")
    return parser


def main(argv: list[str] | None = None) -> int:
    import time

    t_start = time.perf_counter()
    args = build_parser().parse_args(argv)
    os.environ.setdefault("QT_QPA_PLATFORM", "xcb")
    if os.environ["QT_QPA_PLATFORM"] == "xcb" and not os.environ.get("DISPLAY"):
        print("corr-studio: no display (DISPLAY is not set). Run it on a desktop, or on a virtual screen: "
              'xvfb-run -a -s "-screen 0 1600x1000x24" corr-studio --demo --screenshot shot.png',
              file=sys.stderr)
        return 2
    if args.bench:
        from app.bench import run_benchmarks

        return run_benchmarks(t_start)
    from PySide6.QtCore import QTimer
    from PySide6.QtWidgets import QApplication

    from app.main_window import MainWindow

    app = QApplication.instance() or QApplication(sys.argv[:1])
    window = MainWindow(interactive=args.screenshot is None)
    window.show()
    for i, path in enumerate(args.files[:2]):
        window.load_file(path, "source" if i == 0 else "target")
    if args.demo:
        window.load_demo()
    def select_tab() -> None:
        for i in range(window.tabs.count()):
            if args.tab and window.tabs.tabText(i).lower() == args.tab.lower():
                window.tabs.setCurrentIndex(i)

    select_tab()
    if args.pair_mode:
        window.pair_view.mode.setCurrentText(args.pair_mode)
    for item in args.param:
        name, _, value = item.partition("=")
        method = args.method or window.method_box.currentData()
        if method not in window._form_of:
            print(f"corr-studio: --param {item}: no method to apply it to (load inputs or pass --method)",
                  file=sys.stderr)
            return 2
        form = window._form_of[method]
        current = form.values()
        if name not in current:
            print(f"corr-studio: --param {item}: {method} has no parameter {name!r} "
                  f"(it has {', '.join(current)})", file=sys.stderr)
            return 2
        try:
            current[name] = (value.lower() in {"1", "true", "yes", "on"} if isinstance(current[name], bool)
                             else type(current[name])(value))
        except ValueError:
            print(f"corr-studio: --param {item}: cannot interpret {value!r}", file=sys.stderr)
            return 2
        form.set_values(current)
    started = False
    if args.retrieve:
        window.retrieval_view.set_folder(args.retrieve)
        window.tabs.setCurrentWidget(window.retrieval_view)
        window.run_retrieval()
        started = True
    elif args.compare:
        window.tabs.setCurrentWidget(window.compare_view)
        window.run_compare()
        started = True
    elif args.demo or args.method or len(args.files) >= 2:
        if window.method_box.count():
            window.run_method(method=args.method)
            started = True
    if args.screenshot:
        def shoot(*_a):
            select_tab()  # a finished job switches to its own view; show the requested one
            if args.sequence_t is not None and window.sequence_view.positions is not None:
                window.sequence_view.slider.setValue(int(1000 * args.sequence_t / window.sequence_view.t_max.value()))
            if args.torus_function:
                window.product_view.function.setCurrentText(args.torus_function)
            for _ in range(5):
                app.processEvents()
            QTimer.singleShot(500, lambda: (window.save_screenshot(args.screenshot), window.close(), app.quit()))

        if started:
            window.result_ready.connect(shoot)
            window.error_shown.connect(shoot)
        else:
            QTimer.singleShot(1500, shoot)
        QTimer.singleShot(int(args.timeout * 1000), lambda: (window.save_screenshot(args.screenshot), app.quit()))
    return app.exec()


if __name__ == "__main__":
    sys.exit(main())
