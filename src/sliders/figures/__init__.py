"""The figures layer: every picture the package draws, in one print style.

* ``paper``: the paper's ten figures and the command ``python -m sliders.figures``;
* ``study``: a parameter study's figures;
* ``schematics``: the two schematics drawn from the model;
* ``pushed_end``: the chain pushed at one end;
* ``animation``: the tilt animation;
* ``style``: the one print style (sizes, colour maps, saving).

Imports the layers below it (simulation, io, analysis), never the runs
(tests/test_layers.py).  The names of ``paper`` are importable from here.
"""

from .paper import (FIGURE_NAMES, PAPER_FIGURES, SCENE_LETTERS, STATISTICS_NAMES,
                    FigureInputError, PaperFigure, build_parser, draw_figures, fig_bin_heights,
                    fig_cumulated_displacement, fig_force_pdf, fig_scene, fig_single_slider,
                    fig_stopped_force_ratio, figure_list, figure_lookup, force_curves,
                    hot_map_image, load_ensemble_summary, main, rebin_factor, resolve_names,
                    run_ensemble, run_scene, scene_setups, single_slider_run,
                    single_slider_scene)

__all__ = [
    "FIGURE_NAMES", "PAPER_FIGURES", "SCENE_LETTERS", "STATISTICS_NAMES", "FigureInputError",
    "PaperFigure", "build_parser", "draw_figures", "fig_bin_heights", "fig_cumulated_displacement",
    "fig_force_pdf", "fig_scene", "fig_single_slider", "fig_stopped_force_ratio", "figure_list",
    "figure_lookup", "force_curves", "hot_map_image", "load_ensemble_summary", "main",
    "rebin_factor", "resolve_names", "run_ensemble", "run_scene", "scene_setups",
    "single_slider_run", "single_slider_scene",
]
