within ArmExo;
model ArmExoPlant3 "3-DOF exoskeleton (shoulder, elbow, wrist) + linear human arm + LuGre friction + plant-side effects"
  extends ArmExo.Interfaces.PartialPlant(final n = 3);
  parameter ArmExo.Units.Angle_deg posture_deg[3] = {62.708, 77.260, 10.0} "Posture theta0 (shoulder, elbow, wrist)";

  ArmExo.Components.LinearArmImpedance arm(final n = 3,
    M_h = [0.187, 0.084, 0.012; 0.079, 0.060, 0.010; 0.012, 0.010, 0.006],
    B_h = [0.651, 0.239, 0.020; 0.236, 0.407, 0.030; 0.020, 0.030, 0.060],
    K_h = [7.967, 3.187, 0.300; 1.663, 6.901, 0.600; 0.300, 0.600, 3.000]) "Human arm (reference-3dof.md)";
  ArmExo.Components.PlanarExoskeleton3DOF robot(
    q0 = posture_deg*(3.141592653589793/180),
    scale = inertia_mismatch.scale,
    beta = gravity.beta,
    Jm_on_link = if transmission_compliance.on then {0, 0, 0} else {1, 1, 1}) "Exoskeleton links";
  ArmExo.Components.LuGreFriction friction(final n = 3) "Joint friction (motor side with a compliant transmission)";
  ArmExo.Effects.FirstOrderLag actuator_lag(final n = 3) "tau_m -> tau_act";
  ArmExo.Effects.TransmissionCompliance transmission_compliance(final n = 3) "Motor -> link";
  ArmExo.Effects.InterfaceCompliance interface_compliance(final n = 3) "Link -> arm (cuff)";
  ArmExo.Effects.Gravity gravity "Tilt of the plane";
  ArmExo.Effects.InertiaMismatch inertia_mismatch "Scale of a1, a2, a3";
  ArmExo.Effects.FirstOrderLag torque_sensor_lag(final n = 3) "tau_h at the cuff -> sensor reading";

  ArmExo.Units.Angle theta_link[3](each start = 0, each fixed = true) "Link angles (deviation)";
  ArmExo.Units.AngularVelocity w_link[3](each start = 0, each fixed = true) "Link velocities";
  ArmExo.Units.Angle theta_mot[3](each start = 0, each fixed = true) "Motor angles (transmission compliance only)";
  ArmExo.Units.AngularVelocity w_mot[3](each start = 0, each fixed = true) "Motor velocities (transmission compliance only)";
  ArmExo.Units.Angle theta_arm[3](each start = 0, each fixed = true) "Arm angles (interface compliance only)";
  ArmExo.Units.AngularVelocity w_arm[3](each start = 0, each fixed = true) "Arm velocities (interface compliance only)";
  ArmExo.Units.Torque tau_act[3] "Torque applied by the actuators";
  ArmExo.Units.Torque tau_link[3] "Joint torque acting on the links";
  final parameter Real cuff_rigid = if interface_compliance.on then 0 else 1
    "1: rigid cuff (the arm's impedance acts on the links), 0: compliant cuff";
  final parameter Real M_h_adj[3, 3] = [arm.M_h[2, 2]*arm.M_h[3, 3] - arm.M_h[2, 3]*arm.M_h[3, 2], arm.M_h[1, 3]*arm.M_h[3, 2] - arm.M_h[1, 2]*arm.M_h[3, 3], arm.M_h[1, 2]*arm.M_h[2, 3] - arm.M_h[1, 3]*arm.M_h[2, 2];
      arm.M_h[2, 3]*arm.M_h[3, 1] - arm.M_h[2, 1]*arm.M_h[3, 3], arm.M_h[1, 1]*arm.M_h[3, 3] - arm.M_h[1, 3]*arm.M_h[3, 1], arm.M_h[1, 3]*arm.M_h[2, 1] - arm.M_h[1, 1]*arm.M_h[2, 3];
      arm.M_h[2, 1]*arm.M_h[3, 2] - arm.M_h[2, 2]*arm.M_h[3, 1], arm.M_h[1, 2]*arm.M_h[3, 1] - arm.M_h[1, 1]*arm.M_h[3, 2], arm.M_h[1, 1]*arm.M_h[2, 2] - arm.M_h[1, 2]*arm.M_h[2, 1]] "Adjugate of M_h";
  final parameter Real M_h_det = arm.M_h[1, 1]*M_h_adj[1, 1] + arm.M_h[1, 2]*M_h_adj[2, 1] + arm.M_h[1, 3]*M_h_adj[3, 1]
    "det M_h (the compliant cuff needs M_h invertible)";
  final parameter Real M_h_inv[3, 3] = M_h_adj/M_h_det "Inverse of M_h (used with a compliant cuff only)";
  ArmExo.Units.Torque tau_cuff[3] "Torque robot -> arm at the cuff (before the sensor lag)";
  ArmExo.Units.Inertia A_link[3, 3] "Mass matrix of the link equation (M_r, plus M_h with a rigid cuff)";
  Real adj_A_link[3, 3] "Adjugate of A_link";
  Real det_A_link "det A_link";
  ArmExo.Units.Torque f_link[3] "Right-hand side of the link equation";
equation
  // actuator
  actuator_lag.u = tau_m;
  tau_act = actuator_lag.y;
  // transmission: rigid (friction on the link) or compliant (friction and encoder on the motor)
  transmission_compliance.phi_a = theta_mot;
  transmission_compliance.w_a = w_mot;
  transmission_compliance.phi_b = theta_link;
  transmission_compliance.w_b = w_link;
  // rigid (friction on the link) or compliant (friction and encoder on the motor); the
  // switch is a run-time parameter: every state exists, unused ones keep zero derivatives
  for j in 1:3 loop
    der(theta_mot[j]) = if transmission_compliance.on then w_mot[j] else 0;
    der(w_mot[j]) = if transmission_compliance.on then
      (tau_act[j] - friction.tau_f[j] - transmission_compliance.tau[j])/robot.Jm[j] else 0;
    friction.w[j] = if transmission_compliance.on then w_mot[j] else w_link[j];
    tau_link[j] = if transmission_compliance.on then transmission_compliance.tau[j]
      else tau_act[j] - friction.tau_f[j];
    theta[j] = if transmission_compliance.on then theta_mot[j] else theta_link[j];
    omega[j] = if transmission_compliance.on then w_mot[j] else w_link[j];
  end for;
  // links: with a rigid cuff the arm moves with them and its impedance adds to their
  // equation (cuff_rigid = 1); with a compliant cuff the cuff torque acts instead
  robot.theta = theta_link;
  robot.w = w_link;
  der(theta_link) = w_link;
  //   A der(w_link) = f,  A = M_r(q) + cuff_rigid M_h,
  //   f = tau_link - c_r - G - cuff_rigid (B_h w_link + K_h theta_link) - (compliant cuff: tau_cuff),
  // solved by the adjugate here (one division) rather than by the exporter's tearing
  for i in 1:3 loop
    f_link[i] = tau_link[i] - robot.c[i] - robot.G[i]
      - cuff_rigid*(arm.B_h[i, 1]*w_link[1] + arm.B_h[i, 2]*w_link[2] + arm.B_h[i, 3]*w_link[3]
                    + arm.K_h[i, 1]*theta_link[1] + arm.K_h[i, 2]*theta_link[2] + arm.K_h[i, 3]*theta_link[3])
      - (if interface_compliance.on then interface_compliance.tau[i] else 0);
    for k in 1:3 loop
      A_link[i, k] = robot.M[i, k] + cuff_rigid*arm.M_h[i, k];
    end for;
  end for;
  adj_A_link[1, 1] = A_link[2, 2]*A_link[3, 3] - A_link[2, 3]*A_link[3, 2];
  adj_A_link[1, 2] = A_link[1, 3]*A_link[3, 2] - A_link[1, 2]*A_link[3, 3];
  adj_A_link[1, 3] = A_link[1, 2]*A_link[2, 3] - A_link[1, 3]*A_link[2, 2];
  adj_A_link[2, 1] = A_link[2, 3]*A_link[3, 1] - A_link[2, 1]*A_link[3, 3];
  adj_A_link[2, 2] = A_link[1, 1]*A_link[3, 3] - A_link[1, 3]*A_link[3, 1];
  adj_A_link[2, 3] = A_link[1, 3]*A_link[2, 1] - A_link[1, 1]*A_link[2, 3];
  adj_A_link[3, 1] = A_link[2, 1]*A_link[3, 2] - A_link[2, 2]*A_link[3, 1];
  adj_A_link[3, 2] = A_link[1, 2]*A_link[3, 1] - A_link[1, 1]*A_link[3, 2];
  adj_A_link[3, 3] = A_link[1, 1]*A_link[2, 2] - A_link[1, 2]*A_link[2, 1];
  det_A_link = A_link[1, 1]*adj_A_link[1, 1] + A_link[1, 2]*adj_A_link[2, 1] + A_link[1, 3]*adj_A_link[3, 1];
  for i in 1:3 loop
    der(w_link[i]) = (adj_A_link[i, 1]*f_link[1] + adj_A_link[i, 2]*f_link[2] + adj_A_link[i, 3]*f_link[3])/det_A_link;
  end for;
  // cuff and arm; interface_compliance.on is a run-time parameter: every state exists, the
  // arm's own states keep zero derivatives with a rigid cuff
  interface_compliance.phi_a = theta_link;
  interface_compliance.w_a = w_link;
  interface_compliance.phi_b = theta_arm;
  interface_compliance.w_b = w_arm;
  for j in 1:3 loop
    der(theta_arm[j]) = if interface_compliance.on then w_arm[j] else 0;
    der(w_arm[j]) = if interface_compliance.on then
      M_h_inv[j, 1]*(interface_compliance.tau[1] - arm.B_h[1, 1]*w_arm[1] - arm.B_h[1, 2]*w_arm[2] - arm.B_h[1, 3]*w_arm[3]
        - arm.K_h[1, 1]*theta_arm[1] - arm.K_h[1, 2]*theta_arm[2] - arm.K_h[1, 3]*theta_arm[3])
      + M_h_inv[j, 2]*(interface_compliance.tau[2] - arm.B_h[2, 1]*w_arm[1] - arm.B_h[2, 2]*w_arm[2] - arm.B_h[2, 3]*w_arm[3]
        - arm.K_h[2, 1]*theta_arm[1] - arm.K_h[2, 2]*theta_arm[2] - arm.K_h[2, 3]*theta_arm[3])
      + M_h_inv[j, 3]*(interface_compliance.tau[3] - arm.B_h[3, 1]*w_arm[1] - arm.B_h[3, 2]*w_arm[2] - arm.B_h[3, 3]*w_arm[3]
        - arm.K_h[3, 1]*theta_arm[1] - arm.K_h[3, 2]*theta_arm[2] - arm.K_h[3, 3]*theta_arm[3])
      else 0;
    arm.theta[j] = if interface_compliance.on then theta_arm[j] else theta_link[j];
    arm.w[j] = if interface_compliance.on then w_arm[j] else w_link[j];
    arm.a[j] = if interface_compliance.on then der(w_arm[j]) else der(w_link[j]);
    tau_cuff[j] = if interface_compliance.on then interface_compliance.tau[j] else arm.tau[j];
  end for;
  // torque sensor
  torque_sensor_lag.u = tau_cuff;
  tau_h = torque_sensor_lag.y;
  annotation (Documentation(info = "<html>
<p>The three-link plant of docs/spec/reference-3dof.md (ArmExoPlant with a wrist; the C FMU
ArmExoPlant3 has the same parameter names). Nominal
(rigid transmission and cuff):</p>
<pre>
  (M_r(q) + M_h) theta'' = tau_act - tau_f(theta') - c_r - G - B_h theta' - K_h theta
  tau_h = M_h theta'' + B_h theta' + K_h theta
</pre>
<p>q = theta0 + theta. Effects, each off by default: <code>actuator_lag</code>,
<code>transmission_compliance</code>, <code>interface_compliance</code>, <code>gravity</code>,
<code>inertia_mismatch</code>, <code>torque_sensor_lag</code>; they combine. Initial state: all
zero (posture, at rest, z = 0, tau_act = 0, motor aligned). The parameter names equal those
of the C FMU (fmus/variables.py), except that the C FMU also has <code>rk4_step</code>, and the
robot parameters are <code>robot.*</code> in both.</p>
</html>"));
end ArmExoPlant3;
