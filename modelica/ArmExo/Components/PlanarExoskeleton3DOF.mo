within ArmExo.Components;
model PlanarExoskeleton3DOF "Serial 3-link planar exoskeleton (shoulder, elbow, wrist) with the C FMU's parameter names"
  extends ArmExo.Icons.Block;
  parameter ArmExo.Units.Mass m1(min = 0) = 1.5 "Mass of link 1";
  parameter ArmExo.Units.Length L1(min = 0) = 0.30 "Length of link 1";
  parameter ArmExo.Units.Length lc1(min = 0) = 0.15 "Joint 1 to centre of mass of link 1";
  parameter ArmExo.Units.Inertia I1(min = 0) = 0.0113 "Inertia of link 1 about its centre of mass";
  parameter ArmExo.Units.Mass m2(min = 0) = 1.0 "Mass of link 2";
  parameter ArmExo.Units.Length L2(min = 0) = 0.35 "Length of link 2";
  parameter ArmExo.Units.Length lc2(min = 0) = 0.175 "Joint 2 to centre of mass of link 2";
  parameter ArmExo.Units.Inertia I2(min = 0) = 0.0102 "Inertia of link 2 about its centre of mass";
  parameter ArmExo.Units.Mass m3(min = 0) = 0.6 "Mass of link 3 (wrist module and handle)";
  parameter ArmExo.Units.Length L3(min = 0) = 0.12 "Length of link 3";
  parameter ArmExo.Units.Length lc3(min = 0) = 0.06 "Joint 3 to centre of mass of link 3";
  parameter ArmExo.Units.Inertia I3(min = 0) = 0.0008 "Inertia of link 3 about its centre of mass";
  parameter ArmExo.Units.Inertia Jm[3](each min = 0) = {0.010, 0.010, 0.004} "Reflected motor/transmission inertia";
  parameter Real Jm_on_link[3] = {1, 1, 1} "1: Jm moves with the link (rigid transmission), 0: with the motor";
  parameter ArmExo.Units.DimensionlessRatio scale(min = 0) = 1 "Scale of the inertia coefficients (inertia mismatch)";
  parameter ArmExo.Units.Angle beta = 0 "Tilt of the plane from horizontal (gravity)";
  parameter ArmExo.Units.Angle q0[3] = {1.0944, 1.3484, 0.1745} "Posture";
  input ArmExo.Units.Angle theta[3] "Link angles, deviation from the posture";
  input ArmExo.Units.AngularVelocity w[3] "Link velocities";
  output ArmExo.Units.Inertia M[3, 3] "Mass matrix M_r(q)";
  output ArmExo.Units.Torque c[3] "Coriolis and centrifugal torques";
  output ArmExo.Units.Torque G[3] "Gravity torques";
  parameter ArmExo.Units.Acceleration g_n = 9.81 "Gravity of Earth";
  final parameter ArmExo.Units.Inertia a1 = scale*(I1 + m1*lc1^2 + I2 + m2*(L1^2 + lc2^2) + I3 + m3*(L1^2 + L2^2 + lc3^2));
  final parameter ArmExo.Units.Inertia a2 = scale*(I2 + m2*lc2^2 + I3 + m3*(L2^2 + lc3^2));
  final parameter ArmExo.Units.Inertia a3 = scale*(I3 + m3*lc3^2);
  final parameter ArmExo.Units.Inertia b12 = scale*(m2*L1*lc2 + m3*L1*L2);
  final parameter ArmExo.Units.Inertia b13 = scale*m3*L1*lc3;
  final parameter ArmExo.Units.Inertia b23 = scale*m3*L2*lc3;
  final parameter Boolean tilted = beta <> 0 "Gravity acts (a run-time switch: no cosines of q1 when level)";
  final parameter ArmExo.Units.Acceleration g_tilt = g_n*sin(beta) "In-plane gravity";
protected
  ArmExo.Units.Angle q[3] = q0 + theta "Absolute q1, relative q2, q3";
  Real c2, c3, c23, s2, s3, s23 "cos and sin of q2, q3, q2 + q3";
equation
  c2 = cos(q[2]);
  c3 = cos(q[3]);
  c23 = cos(q[2] + q[3]);
  s2 = sin(q[2]);
  s3 = sin(q[3]);
  s23 = sin(q[2] + q[3]);
  M[1, 1] = a1 + 2*b12*c2 + 2*b13*c23 + 2*b23*c3 + Jm_on_link[1]*Jm[1];
  M[1, 2] = a2 + b12*c2 + b13*c23 + 2*b23*c3;
  M[1, 3] = a3 + b13*c23 + b23*c3;
  M[2, 1] = M[1, 2];
  M[2, 2] = a2 + 2*b23*c3 + Jm_on_link[2]*Jm[2];
  M[2, 3] = a3 + b23*c3;
  M[3, 1] = M[1, 3];
  M[3, 2] = M[2, 3];
  M[3, 3] = a3 + Jm_on_link[3]*Jm[3];
  // Christoffel symbols of the first kind of M_r (reference-3dof.md), written out
  c[1] = -b12*s2*(2*w[1]*w[2] + w[2]^2) - b13*s23*(w[2] + w[3])*(2*w[1] + w[2] + w[3])
    - b23*s3*w[3]*(2*w[1] + 2*w[2] + w[3]);
  c[2] = (b12*s2 + b13*s23)*w[1]^2 - b23*s3*w[3]*(2*w[1] + 2*w[2] + w[3]);
  c[3] = b13*s23*w[1]^2 + b23*s3*(w[1] + w[2])^2;
  G[3] = if tilted then g_tilt*m3*lc3*cos(q[1] + q[2] + q[3]) else 0;
  G[2] = if tilted then g_tilt*(m2*lc2 + L2*m3)*cos(q[1] + q[2]) + G[3] else 0;
  G[1] = if tilted then g_tilt*(m1*lc1 + L1*(m2 + m3))*cos(q[1]) + G[2] else 0;
  annotation (Documentation(info = "<html><p>The three-link equations of docs/spec/reference-3dof.md written out
(M_r as printed there, the Coriolis torques from its Christoffel symbols, gravity from the
potential energy), under the C FMU's names (robot.m3, ...): PlanarExoskeletonNDOF for n = 3,
without the nested array comprehensions the exporter (modelica 0.0.205) cannot flatten.</p></html>"));
end PlanarExoskeleton3DOF;
