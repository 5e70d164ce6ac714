"""The 6R test arm of the URDF tests, as URDF text (no robocal imports: the independent generators
use it too): `BARE_URDF` without inertials, `URDF` with the link masses and centres of mass `INERTIAL`."""

BARE_URDF = """<robot name="r6">
  <link name="b"/><link name="l1"/><link name="l2"/><link name="l3"/><link name="l4"/><link name="l5"/><link name="l6"/>
  <joint name="j1" type="revolute"><parent link="b"/><child link="l1"/><origin xyz="0 0 0.2"/><axis xyz="0 0 1"/>
    <limit lower="-3" upper="3" effort="1" velocity="1"/></joint>
  <joint name="j2" type="revolute"><parent link="l1"/><child link="l2"/><origin xyz="0 0.1 0" rpy="1.5708 0 0"/>
    <axis xyz="0 0 1"/><limit lower="-2" upper="2" effort="1" velocity="1"/></joint>
  <joint name="j3" type="revolute"><parent link="l2"/><child link="l3"/><origin xyz="0.4 0 0"/><axis xyz="0 0 1"/>
    <limit lower="-2.5" upper="2.5" effort="1" velocity="1"/></joint>
  <joint name="j4" type="revolute"><parent link="l3"/><child link="l4"/><origin xyz="0.35 0 0" rpy="0 1.5708 0"/>
    <axis xyz="0 0 1"/><limit lower="-3" upper="3" effort="1" velocity="1"/></joint>
  <joint name="j5" type="revolute"><parent link="l4"/><child link="l5"/><origin xyz="0 0 0.1" rpy="-1.5708 0 0"/>
    <axis xyz="0 1 0"/><limit lower="-2" upper="2" effort="1" velocity="1"/></joint>
  <joint name="j6" type="continuous"><parent link="l5"/><child link="l6"/><origin xyz="0 0 0.08"/><axis xyz="0 0 1"/></joint>
</robot>
"""

INERTIAL = {"l1": (6.0, "0 0 -0.05"), "l2": (9.0, "0.2 0 0.02"), "l3": (6.0, "0.17 0 0"), "l4": (2.5, "0 0 0.05"),
            "l5": (1.5, "0 0 0.03"), "l6": (1.0, "0 0 0.04")}
URDF = BARE_URDF
for _ln, (_m, _c) in INERTIAL.items():
    URDF = URDF.replace(f'<link name="{_ln}"/>', f'<link name="{_ln}"><inertial><origin xyz="{_c}"/><mass value="{_m}"/>'
                        '<inertia ixx="0.01" ixy="0" ixz="0" iyy="0.01" iyz="0" izz="0.01"/></inertial></link>')

# A 6R arm with a spherical wrist (j4, j5, j6 axes meet; no two wrist axes coincide): any camera pose
# near its home is reachable (the test arm above has coincident j4 and j5 axes).
WRIST_URDF = """<robot name="six">
  <link name="base"/><link name="l1"/><link name="l2"/><link name="l3"/><link name="l4"/><link name="l5"/>
  <link name="l6"/><link name="tool"/>
  <joint name="j1" type="revolute"><parent link="base"/><child link="l1"/><origin xyz="0 0 0.4"/>
    <axis xyz="0 0 1"/><limit lower="-3" upper="3" effort="1" velocity="1"/></joint>
  <joint name="j2" type="revolute"><parent link="l1"/><child link="l2"/><origin xyz="0.1 0 0" rpy="1.5707963 0 0"/>
    <axis xyz="0 0 1"/><limit lower="-3" upper="3" effort="1" velocity="1"/></joint>
  <joint name="j3" type="revolute"><parent link="l2"/><child link="l3"/><origin xyz="0.45 0 0"/>
    <axis xyz="0 0 1"/><limit lower="-3" upper="3" effort="1" velocity="1"/></joint>
  <joint name="j4" type="revolute"><parent link="l3"/><child link="l4"/><origin xyz="0.05 0.4 0" rpy="-1.5707963 0 0"/>
    <axis xyz="0 0 1"/><limit lower="-3" upper="3" effort="1" velocity="1"/></joint>
  <joint name="j5" type="revolute"><parent link="l4"/><child link="l5"/><origin xyz="0 0 0" rpy="1.5707963 0 0"/>
    <axis xyz="0 0 1"/><limit lower="-3" upper="3" effort="1" velocity="1"/></joint>
  <joint name="j6" type="revolute"><parent link="l5"/><child link="l6"/><origin xyz="0 0 0" rpy="-1.5707963 0 0"/>
    <axis xyz="0 0 1"/><limit lower="-3" upper="3" effort="1" velocity="1"/></joint>
  <joint name="flange" type="fixed"><parent link="l6"/><child link="tool"/><origin xyz="0.02 0 0.12"/></joint>
</robot>
"""
