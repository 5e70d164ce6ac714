"""Dynamics: what moves the robot — inertial parameters, friction, drives — identified from joint
position and effort logs.

Pure numpy (functional core); the stages call it, files stay at the edges:

- `effort`: the effort → torque conversion a recording declares (scale, offset, differential mixes);
- `rigid_body`: the URDF's tree reduced to the recorded joints (Pinocchio), its joint-torque regressor
  and standard inertial parameters;
- `signals`: zero-phase filtering, differentiation, decimation;
- `design`: the regressor of one model choice (inertial + friction + armature columns, fitted joints);
- `base`: base parameters by QR with column pivoting;
- `solve`: ordinary, weighted and physically consistent (SDP) least squares;
- `crossval`: contiguous-block cross-validation, the held-out arbiter of every model choice;
- `identify`: the whole identification (`identify`, `predict`), the object later stages read.
"""
