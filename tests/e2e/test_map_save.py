"""Saving a running agent's map: the agent in this process with its real Zenoh session, scans
and odometry over the bus, and ``loci map save`` as a user types it in another process."""

from __future__ import annotations

import asyncio
import json
import time
from pathlib import Path

import numpy as np
import zenoh
from scipy import ndimage
from support.cli import loci
from support.runtime import ROBOT, _room_scan, write_config

from agent.bus.bridge import publish_stream
from agent.bus.codecs import JSON_ENCODING
from agent.bus.keys import stream_key
from agent.bus.queryable import query_state, request
from agent.bus.session import BusConfig, bus_session, listening_endpoints
from agent.bus.testing import settle
from agent.config import load_config
from agent.runtime import Agent
from drivers.messages import Pose2D
from knowledge.labels import read_label_image
from knowledge.metric.grid import OccupancyGrid
from knowledge.places.model import PlaceModel, default_model_path

KEY = stream_key(ROBOT, "map/save")


def _room() -> OccupancyGrid:
    occ = np.ones((82, 162), dtype=bool)
    occ[1:-1, 1:-1] = False
    return OccupancyGrid.from_masks(occ, 0.05, name="room")  # an 8 m x 4 m room, origin (0, 0)


def test_a_running_agent_saves_its_map_on_request_and_refuses_bad_folders(tmp_path: Path) -> None:
    room = _room()
    model = PlaceModel.load(default_model_path())
    out = tmp_path / "maps" / "today"

    async def main() -> None:
        with bus_session(BusConfig()) as session:
            (endpoint,) = listening_endpoints(session)
            cfg = load_config(write_config(tmp_path, endpoint, None), env={})
            stop, ready = asyncio.Event(), asyncio.Event()
            agent = Agent(cfg, model=model, on_ready=lambda _: ready.set())
            run = asyncio.create_task(agent.run(stop))
            await asyncio.wait_for(ready.wait(), 20)
            assert agent.session is not None
            await asyncio.to_thread(settle, session, agent.session)
            (agent_at,) = agent.endpoints

            def save(*extra: str | Path) -> tuple[int, str, str]:
                done = loci("map", "save", *extra, "--robot", ROBOT, "--connect", agent_at, "--timeout", "10")
                return done.returncode, done.stdout, done.stderr

            # no scan yet: nothing to save, and nothing made
            rc, _, err = await asyncio.to_thread(save, "--out", out)
            assert rc == 2 and "no map yet" in err, err
            assert not out.exists()

            scans, odom = publish_stream(session, ROBOT, "scan"), publish_stream(session, ROBOT, "odom")
            for seq in range(50):  # along the room's middle, 1 m to 3.45 m
                now, pose = time.time(), (1.0 + 0.05 * seq, 2.0, 0.0)
                odom.put(Pose2D(*pose, stamp=now))
                scans.put(_room_scan(room, pose, now, seq))
                await asyncio.sleep(0.025)
            odom.put(Pose2D(3.5, 2.0, 0.0, stamp=time.time() + 0.05))  # the last scan's odometry
            await asyncio.sleep(0.5)
            assert agent.pipeline is not None and agent.pipeline.scans >= 40

            rc, stdout, err = await asyncio.to_thread(save, "--out", out, "--json")
            assert rc == 0, err
            saved = json.loads(stdout)
            assert saved["schema"] == "loci.map_saved/1" and saved["dir"] == str(out)
            assert saved["frame_id"] == "odom" and saved["scans"] == agent.pipeline.scans
            assert sorted(Path(f).name for f in saved["files"]) == [
                "labels.png",
                "labels.yaml",
                "map.pgm",
                "map.yaml",
            ]
            before = {p.name: p.read_bytes() for p in out.iterdir()}

            # a folder that holds a map already is left alone without --overwrite
            rc, _, err = await asyncio.to_thread(save, "--out", out)
            assert rc == 2 and "already holds a saved map" in err, err
            # a path through a file, and a relative path sent by hand: refused, nothing written
            blocker = tmp_path / "not_a_folder"
            blocker.write_text("keep me")
            rc, _, err = await asyncio.to_thread(save, "--out", blocker / "map")
            assert rc == 2 and f"cannot save the map in {blocker / 'map'}" in err, err
            assert blocker.read_text() == "keep me"
            (relative,) = await asyncio.to_thread(
                request, session, KEY, {"schema": "loci.map_save/1", "dir": "maps"}, "loci.map_save/1"
            )
            assert relative.value is None and relative.error is not None and "absolute path" in relative.error
            # a query that is not a loci.map_save/1 request is answered with what is wrong
            bad = await asyncio.to_thread(
                lambda: list(
                    session.get(
                        KEY,
                        payload=b'{"schema": "loci.map_save/1", "folder": "/tmp"}',
                        encoding=zenoh.Encoding(f"{JSON_ENCODING};loci.map_save/1"),
                        timeout=5.0,
                    )
                )
            )
            assert len(bad) == 1 and bad[0].err is not None
            assert b"missing required field 'dir'" in bad[0].err.payload.to_bytes()
            assert {p.name: p.read_bytes() for p in out.iterdir()} == before
            # the state queryables still answer beside it
            assert (await asyncio.to_thread(query_state, session, f"loci/{ROBOT}/state/graph", 3.0))[0].value

            rc, stdout, err = await asyncio.to_thread(save, "--out", out, "--overwrite")
            assert rc == 0 and f"saved the map of {ROBOT} in {out}" in stdout, err
            stop.set()
            await asyncio.wait_for(run, 10)

    asyncio.run(main())
    # the saved map: the room's walls where they are, its inside free, labels on the free cells
    grid = OccupancyGrid.load(out / "map.yaml")
    walls = ndimage.binary_dilation(room.occupied, iterations=2)
    cells = room.world_to_cell(grid.cell_to_world(np.argwhere(grid.occupied)))
    assert len(cells) > 300 and room.in_bounds(cells).all()
    assert walls[cells[:, 0], cells[:, 1]].mean() > 0.98
    inside = room.world_to_cell(grid.cell_to_world(np.argwhere(grid.free)))
    assert room.free[inside[:, 0], inside[:, 1]].mean() > 0.99
    assert grid.free.sum() > 0.8 * room.free.sum()  # the room was seen whole
    codes = read_label_image(out / "labels.png")
    assert codes.shape == grid.shape and not codes[~grid.free].any() and (codes[grid.free] > 0).mean() > 0.99
