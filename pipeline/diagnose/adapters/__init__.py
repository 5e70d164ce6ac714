"""What is system-specific in a diagnosis (`adapter.Adapter`), one module per kind of system:

- `touch`: the arc welder's touch campaign (`touch_table`: its diagnosis table from a recording;
  `touch_variables`: its extra lack-of-fit variables);
- `delta`: a Delta robot measured by a laser tracker;
- `scanner`: the SCORBOT laser-stripe scanner (`scanner_noise`: its pose-error model);
- `urdf_robot`: any URDF robot with a generic measurement type.
"""
