"""The library of physics terms a geometric calibration leaves out.

A term (`term.Effect`) is a named, located model with a few physical parameters θ; it declares, as
data on the term, its basis (the pure numpy function of (geometry x, data table) whose product with
θ is the term's value — δq in rad per joint, a tip displacement in m in the jig frame {W}, or a face
coordinate in m — and which is therefore also the term's Jacobian with respect to θ), its signature
(`term.signature`: the residual change per unit θ, m/unit), its plausible size (`plausible`, in
`units`), its immaterial size (`tolerance`) and its look-alikes (`confounders`: terms whose union may
absorb it).  One module per family:

- `gravity`: gravity torques of a serial arm's lumped masses (N·m), shared by compliance terms;
- `joint`: terms acting through a joint reading (compliance, backlash, scale, eccentricity,
  transmission error, couplings between joints);
- `thermal`: drift of the tip and growth of the links, against time or a recorded temperature;
- `touch_probe`: trigger pretravel and latency of a touch sensor;
- `jig`: the touched faces' offset, tilt and flatness;
- `wire`: the welding wire's stick-out;
- `urdf_gravity`: gravity torques of a URDF robot's inertials;
- `lens`: the scanner camera's lens terms beyond one radial term (with their Jacobian) and the stripe geometry;
- `touch`: the arc-welder touch campaign's catalogue of the joint, thermal, touch-probe, jig and wire terms.

Importing a module here imports nothing of the diagnosis machinery (`inference`, `verdict`,
`adapters`): identification can use the terms directly.
"""
