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
  ArmExo.Components.PlanarExoskeletonNDOF links(final n = 3, m = {m1, m2, m3}, L = {L1, L2, L3},
    lc = {lc1, lc2, lc3}, I = {I1, I2, I3}, Jm = Jm, Jm_on_link = Jm_on_link, scale = scale,
    beta = beta, q0 = q0) "The n-link equations";
equation
  links.theta = theta;
  links.w = w;
  M = links.M;
  c = links.c;
  G = links.G;
  annotation (Documentation(info = "<html><p>PlanarExoskeletonNDOF with n = 3 and the
parameters of docs/spec/reference-3dof.md under the C FMU's names (robot.m3, ...).</p></html>"));
end PlanarExoskeleton3DOF;
