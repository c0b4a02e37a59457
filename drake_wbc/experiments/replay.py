"""A replay of a simulated run as a self-contained Meshcat HTML page.

`ReplayRecorder` adds a `MeshcatVisualizer` (illustration role) to a diagram
and records every pose it publishes during a simulation into a Meshcat
animation; `write` saves the animation with the scene as one HTML file that
opens in any browser, with no server and no network. The page plays the run
once when it opens and stays on its last frame; "Open Controls", then
"Animations", has play, pause, reset and a time slider.

Everything registered in the diagram's `SceneGraph` with the illustration
role is drawn and animated: the robot, and any other geometry source such
as moving people, whose frames' poses reach SceneGraph from their own
systems.

The order of the calls::

    builder = DiagramBuilder()
    plant, scene_graph = AddMultibodyPlantSceneGraph(builder, time_step=1e-3)
    ...                                    # add models, Finalize, wire up
    recorder = ReplayRecorder.add_to(builder, scene_graph)   # records now
    diagram = builder.Build()
    simulator = Simulator(diagram)
    simulator.AdvanceTo(duration)          # each publish adds a frame
    recorder.add_path("tcp", points_W)     # optional: lines in the scene
    recorder.write("out/run/replay.html")

Recording starts inside `add_to`, so it is on before the simulator's first
publish (at initialization, time 0) whatever happens next. A frame is kept
per publish period of simulated time; publishing at the same time twice
(e.g. a second simulation from time 0 on the same diagram) overwrites
frames. Without a simulator, set the diagram context's time and call
`diagram.ForcedPublish(context)` once per frame. While it records, the
live Meshcat at `recorder.meshcat.web_url()` shows the run too.

Size: a page holds Meshcat's viewer and the scene's meshes (2.3 MB for
the robot alone) plus about 41 kB a second of run at 30 frames a second
for the robot's 11 moving bodies (measured with every body moving in every
frame): 2.7 MB for 10 s, 4.8 MB for 60 s. Each further moving body adds
about 4 kB a second; a longer `publish_period` shrinks the animation in
proportion (60 s at 15 frames a second: 3.5 MB).
"""

import logging
from pathlib import Path

import numpy as np
from pydrake.geometry import (
    Meshcat,
    MeshcatVisualizer,
    MeshcatVisualizerParams,
    Rgba,
    Role,
)

from drake_wbc.math.validation import as_matrix, positive

DEFAULT_PUBLISH_PERIOD = 1.0 / 30.0
"""The replay's frame period, s: 30 frames a second of simulated time."""

PATHS_PREFIX = "/paths"
"""Where `ReplayRecorder.add_path` puts its lines in Meshcat's scene tree."""


def quiet_meshcat():
    """Returns a new `Meshcat` without Drake's note about its live server.

    Meshcat always serves its scene on a local port and logs the address;
    for a program whose product is a static page that note misleads, so it
    is held back while the server starts (the address stays available from
    `web_url()`).
    """
    drake_logger = logging.getLogger("drake")
    previous_level = drake_logger.level
    drake_logger.setLevel(logging.WARNING)
    try:
        return Meshcat()
    finally:
        drake_logger.setLevel(previous_level)


def write_static_html(meshcat, path):
    """Writes `meshcat`'s scene (and animation, if published) to `path`.

    Args:
        meshcat: the `Meshcat` whose `StaticHtml()` is written.
        path: the HTML file to write; its folder is created.

    Returns:
        pathlib.Path: the written file.
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(meshcat.StaticHtml(), encoding="utf-8")
    return path


class ReplayRecorder:
    """Records a simulated run and writes it as a Meshcat HTML replay.

    Make one with `add_to` while the diagram is being built (see the
    module's docstring for the order of the calls); it owns the
    `MeshcatVisualizer` it adds and the recording of its `Meshcat`.

    Attributes:
        meshcat: the `Meshcat` the replay is recorded in.
        visualizer: the `MeshcatVisualizer` in the diagram.
        publish_period: the frame period of the replay, s.
    """

    def __init__(self, meshcat, visualizer, publish_period):
        self.meshcat = meshcat
        self.visualizer = visualizer
        self.publish_period = publish_period
        self._recording = False

    @classmethod
    def add_to(
        cls,
        builder,
        scene_graph,
        publish_period=DEFAULT_PUBLISH_PERIOD,
        meshcat=None,
    ):
        """Adds a visualizer to `builder` and starts recording.

        Args:
            builder: the `DiagramBuilder` that holds `scene_graph`; not yet
                built.
            scene_graph: the `SceneGraph` whose illustration geometry is
                drawn, or its query output port (e.g. the `query_object`
                port a station diagram exports).
            publish_period: the frame period of the replay, s (> 0); the
                visualizer publishes once per period of simulated time.
            meshcat: the `Meshcat` to draw in; a new one (see
                `quiet_meshcat`) if None. Any recording it holds is
                discarded.

        Returns:
            ReplayRecorder: the recorder, already recording.

        Raises:
            ValueError: if `publish_period` is not a positive number.
        """
        publish_period = positive("publish_period", publish_period)
        meshcat = quiet_meshcat() if meshcat is None else meshcat
        params = MeshcatVisualizerParams(
            role=Role.kIllustration, publish_period=publish_period
        )
        visualizer = MeshcatVisualizer.AddToBuilder(
            builder, scene_graph, meshcat, params
        )
        recorder = cls(meshcat, visualizer, publish_period)
        recorder._start()
        return recorder

    @property
    def frames_per_second(self):
        """The replay's frame rate, 1 / publish_period."""
        return 1.0 / self.publish_period

    @property
    def is_recording(self):
        """Whether publishes are being recorded (until `write`)."""
        return self._recording

    def _start(self):
        self.meshcat.DeleteRecording()
        # Each publish is also sent to the live scene, so the page's static
        # scene holds the last pose and a browser on web_url() shows the run.
        self.meshcat.StartRecording(
            frames_per_second=self.frames_per_second,
            set_visualizations_while_recording=True,
        )
        # Meshcat files a publish at time t under frame floor(t * fps). The
        # k-th periodic publish is at k * period, which floating point puts
        # a hair below k / fps now and then (k = 31, 62, ... at 30 fps),
        # so it would overwrite frame k - 1 and leave frame k empty.
        # Shifting the animation's start by half a frame rounds instead.
        self.meshcat.get_mutable_recording().set_start_time(
            -0.5 * self.publish_period
        )
        self._recording = True

    def add_path(self, name, points_W, rgba=None, line_width=3.0):
        """Draws a polyline through `points_W` in the replay's scene.

        The line is part of the scene for the whole replay (Meshcat's
        animations move objects but do not create them), e.g. the end
        effector's trajectory, added after the run.

        Args:
            name: the line's name, a Meshcat path under `PATHS_PREFIX`
                (e.g. "tcp" or "people/alice"); adding a name again
                replaces the line.
            points_W: (N, 3) points in the world frame, m, N >= 2.
            rgba: the line's colour, a `pydrake.geometry.Rgba`; orange if
                None.
            line_width: the width in pixels (> 0; many WebGL
                implementations draw 1 pixel whatever the width).

        Returns:
            str: the line's Meshcat path.

        Raises:
            ValueError: for an empty or malformed name, fewer than two
                points, a non-finite point or a non-positive width.
        """
        if not isinstance(name, str) or not name.strip("/") or any(
            not part for part in name.strip("/").split("/")
        ):
            raise ValueError(
                f"name = {name!r} is not allowed: must be a non-empty "
                "Meshcat path such as 'tcp' or 'people/alice'"
            )
        points_W = as_matrix("points_W", points_W, (None, 3))
        if points_W.shape[0] < 2:
            raise ValueError(
                f"points_W has {points_W.shape[0]} point(s), which is not "
                "allowed: a path needs at least 2"
            )
        line_width = positive("line_width", line_width)
        rgba = Rgba(1.0, 0.45, 0.0, 1.0) if rgba is None else rgba
        if not isinstance(rgba, Rgba):
            raise ValueError(
                f"rgba = {rgba!r} is not allowed: must be a "
                "pydrake.geometry.Rgba or None"
            )
        path = f"{PATHS_PREFIX}/{name.strip('/')}"
        self.meshcat.SetLine(
            path, np.asfortranarray(points_W.T), line_width, rgba
        )
        return path

    def write(self, path):
        """Stops recording and writes the replay page to `path`.

        Publishes after this call are not recorded. Calling `write` again
        writes the same recording (with any paths added since).

        Args:
            path: the HTML file to write; its folder is created.

        Returns:
            pathlib.Path: the written file.
        """
        if self._recording:
            self.meshcat.StopRecording()
            self._recording = False
        self.meshcat.PublishRecording()
        return write_static_html(self.meshcat, path)
