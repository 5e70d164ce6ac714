"""The reference systems robocal knows, each declared once as a composition of generic parts
(`pipeline.systems.system.System`).  A new system is one more declaration here.

The diagnosis parts are named by string only (`pipeline.diagnose.*`): nothing here imports them.
"""

from __future__ import annotations

from pipeline.systems.system import System

ARC_WELDER = System(
    name="arc-welder", measurement_channel="/touch/contact",
    loader="pipeline.systems.arc_welder", model="pipeline.systems.arc_welder:TouchModel",
    measurement="pipeline.measurements.plane:PlaneModel", kinematics="pipeline.models.serial_arm:SerialArm",
    fixture="pipeline.models.jig", physics="pipeline.diagnose.adapters.touch:touch_adapter",
    simulator="pipeline.simulate.arc_welder", visualizer="pipeline.visualize.arc_welder",
    planner="pipeline.plan.arc_welder", compensator="pipeline.compensate.serial")

DELTA_TRACKER = System(
    name="delta-tracker", measurement_channel="/tracker/point",
    loader="pipeline.systems.delta_tracker", model="pipeline.systems.delta_tracker:TrackerModel",
    measurement="pipeline.measurements.registered_point:RegisteredPointModel",
    kinematics="pipeline.models.delta_arm:DeltaKinematics",
    physics="pipeline.diagnose.adapters.delta:adapter", simulator="pipeline.simulate.delta_tracker",
    visualizer="pipeline.visualize.delta_tracker", planner="pipeline.plan.delta_tracker",
    compensator="pipeline.compensate.delta")

SCORBOT_SCANNER = System(
    name="scorbot-scanner", measurement_channel="/scanner/stripe",
    loader="pipeline.systems.scorbot_scanner", model="pipeline.systems.scorbot_scanner:ScannerModel",
    measurement="pipeline.measurements.sensed_point:SensedPointModel", kinematics="pipeline.models.serial_arm:SerialArm",
    instrument="pipeline.models.stripe_sensor:StripeSensor",
    physics="pipeline.diagnose.adapters.scanner:adapter", simulator="pipeline.simulate.scorbot_scanner",
    visualizer="pipeline.visualize.scorbot_scanner", planner="pipeline.plan.scorbot_scanner",
    compensator="pipeline.compensate.serial")

URDF = System(
    name="urdf", measurement_channel="/measure/point",
    loader="pipeline.systems.urdf_robot", model="pipeline.systems.urdf_robot:model_for",
    measurement="pipeline.measurements.point:PointModel",  # or pose, plane, coincidence: the campaign's measure
    kinematics="pipeline.models.urdf_arm:UrdfArm", physics="pipeline.diagnose.adapters.urdf_robot:adapter",
    simulator="pipeline.simulate.urdf_robot", planner="pipeline.plan.urdf_robot",
    compensator="pipeline.compensate.serial")

# In the order detection tries their measurement channels.
CATALOG: dict[str, System] = {s.name: s for s in (ARC_WELDER, DELTA_TRACKER, SCORBOT_SCANNER, URDF)}
