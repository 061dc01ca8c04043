"""Simulation: tunnels, beacons, clutter and scanners, the fixture factory of MAST.

Ray casting is vectorised over beams; every beam keeps what it really hit,
so tests and benchmarks know which panels a scan saw.
"""

from mast.sim.design import BeaconDesign, paper_design, polyline_design, random_design
from mast.sim.drive import DriveScene, drive_scenario, drive_scene
from mast.sim.hard import drift_scene, hard_scene
from mast.sim.scanner import SCANNERS, ScannerModel, SimulatedScan, scanner_model, simulate_scan
from mast.sim.scenarios import (
    PAPER_VARIANTS,
    SCENARIOS,
    TRUTH_COLUMNS,
    build_scenario,
    paper_scenario,
    paper_scene,
    random_scenario,
    random_scene,
    write_scenario,
)
from mast.sim.scene import Scene, Shot
from mast.sim.tunnel import Roughness, Tunnel, roughen
from mast.sim.world import Surface, World, WorldBuilder

__all__ = [
    "PAPER_VARIANTS",
    "SCANNERS",
    "SCENARIOS",
    "TRUTH_COLUMNS",
    "BeaconDesign",
    "DriveScene",
    "Roughness",
    "ScannerModel",
    "Scene",
    "Shot",
    "SimulatedScan",
    "Surface",
    "Tunnel",
    "World",
    "WorldBuilder",
    "build_scenario",
    "drift_scene",
    "drive_scenario",
    "drive_scene",
    "hard_scene",
    "paper_design",
    "paper_scenario",
    "paper_scene",
    "polyline_design",
    "random_design",
    "random_scenario",
    "random_scene",
    "roughen",
    "scanner_model",
    "simulate_scan",
    "write_scenario",
]
