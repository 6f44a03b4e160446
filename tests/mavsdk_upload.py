"""Import a QGroundControl .plan with MAVSDK and upload it over loopback UDP to a second
MAVSDK instance configured as an autopilot; print, as one JSON line, every item the
autopilot received (a test helper, run in a process of its own: MAVSDK's C++ core keeps
threads). Usage: ``python tests/mavsdk_upload.py PLAN PORT``."""

from __future__ import annotations

import json
import sys
import threading

from mavsdk.component_type import ComponentType
from mavsdk.mavsdk import Configuration, Mavsdk
from mavsdk.plugins.mission_raw import MissionRaw
from mavsdk.plugins.mission_raw_server import MissionRawServer


def main() -> None:
    plan, port = sys.argv[1], int(sys.argv[2])
    autopilot = Mavsdk(Configuration.create_with_component_type(ComponentType.AUTOPILOT))
    autopilot.add_any_connection(f"udpin://127.0.0.1:{port}")
    server = MissionRawServer(autopilot.server_component())
    received: list = []
    done = threading.Event()

    def on_mission(result, mission, *_):
        received.append(mission)
        done.set()

    server.subscribe_incoming_mission(on_mission)
    station = Mavsdk(Configuration.create_with_component_type(ComponentType.GROUND_STATION))
    station.add_any_connection(f"udpout://127.0.0.1:{port}")
    system = station.first_autopilot(10.0)
    if system is None:
        raise SystemExit("no autopilot found on loopback")
    mission = MissionRaw(system)
    imported = mission.import_qgroundcontrol_mission(plan)
    mission.upload_mission(imported.mission_items)
    if not done.wait(10.0):
        raise SystemExit("the autopilot received no mission")
    items = [
        {"seq": i.seq, "frame": i.frame, "command": i.command, "x": i.x, "y": i.y, "z": i.z,
         "params": [i.param1, i.param2, i.param3, i.param4]}
        for i in received[0].mission_items
    ]  # fmt: skip
    print("RECEIVED " + json.dumps({"imported": len(imported.mission_items), "items": items}))
    sys.stdout.flush()
    station.destroy()
    autopilot.destroy()


if __name__ == "__main__":
    main()
