"""The Foxglove layout of the live view, built with ``foxglove.layouts`` (the SDK's layout types).

``python -m agent.live.layout`` writes ``deploy/foxglove/genius-loci.json``: a 3D panel with
every layer (the scans, the occupancy grid, the labelled map, the graph, the areas, the
people; the map frame fixed, following the base), a plot of the place histogram
(``/place.probabilities.*``), a state-transition strip of the current class, and the
conversation log. Import it in the Foxglove app (Layouts → Import from file). A test checks
the committed file is what this module builds.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import foxglove.layouts as fl

from agent.bus.scene import class_rgba
from knowledge.labels import CLASS_NAMES

#: Where the layout file lives in the repository.
LAYOUT_FILE = Path(__file__).resolve().parents[2] / "deploy" / "foxglove" / "genius-loci.json"


def _hex(label: str) -> str:
    r, g, b, _ = class_rgba(label)
    return "#{:02x}{:02x}{:02x}".format(*(round(255 * c) for c in (r, g, b)))


def build_layout() -> fl.Layout:
    """The layout (see the module docstring)."""
    grid = fl.BaseRendererGridTopicSettings
    three_d = fl.ThreeDeePanel(
        title="genius-loci: every layer",
        config=fl.ThreeDeeConfig(
            fixed_frame="map",
            follow_tf="base_link",
            follow_mode="follow-position",
            topics={
                "/scan": fl.BaseRendererLaserScanTopicSettings(
                    visible=True, point_size=4, flat_color="#e03030"
                ),
                "/scan/full": fl.BaseRendererLaserScanTopicSettings(
                    visible=False, point_size=3, flat_color="#3080e0"
                ),
                "/map": grid(visible=True, color_mode="rgba-fields", draw_behind=True),
                "/labels": grid(visible=True, color_mode="rgba-fields", draw_behind=True),
                "/graph": fl.BaseRendererSceneUpdateTopicSettings(visible=True),
                "/areas": fl.BaseRendererSceneUpdateTopicSettings(visible=True),
                "/people": fl.BaseRendererSceneUpdateTopicSettings(visible=True),
            },
        ),
    )
    classes = [name for _, name in sorted(CLASS_NAMES.items())]
    plot = fl.PlotPanel(
        title="place histogram",
        config=fl.PlotConfig(
            paths=[
                fl.PlotSeries(value=f"/place.probabilities.{c}", label=c, color=_hex(c), enabled=True)
                for c in classes
            ],
            min_y_value=0.0,
            max_y_value=1.0,
            show_legend=True,
        ),
    )
    states = fl.StateTransitionsPanel(
        title="current place",
        config=fl.StateTransitionsConfig(
            paths=[
                fl.StateTransitionsSeries(value="/place.label", label="class"),
                fl.StateTransitionsSeries(value="/place.node", label="node"),
            ]
        ),
    )
    conversation = fl.LogPanel(
        title="conversation", config=fl.LogConfig(topic_to_render="/conversation", show_name=True)
    )
    side = fl.SplitContainer(
        direction="column",
        items=[
            fl.SplitItem(proportion=2, content=plot),
            fl.SplitItem(proportion=1, content=states),
            fl.SplitItem(proportion=2, content=conversation),
        ],
    )
    return fl.Layout(
        content=fl.SplitContainer(
            direction="row",
            items=[fl.SplitItem(proportion=2, content=three_d), fl.SplitItem(proportion=1, content=side)],
        )
    )


def layout_json() -> str:
    """The layout as the file holds it (indented JSON, a newline at the end)."""
    return json.dumps(json.loads(build_layout().to_json()), indent=2, sort_keys=True) + "\n"


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description="Write the Foxglove layout of the live view.")
    p.add_argument(
        "--out", type=Path, default=LAYOUT_FILE, help=f"the layout file (a file; default {LAYOUT_FILE})"
    )
    args = p.parse_args(argv)
    from knowledge.fileio import atomic_write_text

    atomic_write_text(args.out, layout_json())
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
