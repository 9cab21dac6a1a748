within ArmExo.Components;
model PlanarExoskeleton2DOF "Serial 2-link planar exoskeleton: mass matrix, Coriolis/centrifugal and gravity torques"
  extends ArmExo.Icons.Block;
  parameter ArmExo.Units.Mass m1(min = 0) = 1.5 "Mass of link 1";
  parameter ArmExo.Units.Length L1(min = 0) = 0.30 "Length of link 1";
  parameter ArmExo.Units.Length lc1(min = 0) = 0.15 "Joint 1 to centre of mass of link 1";
  parameter ArmExo.Units.Inertia I1(min = 0) = 0.0113 "Inertia of link 1 about its centre of mass";
  parameter ArmExo.Units.Mass m2(min = 0) = 1.0 "Mass of link 2";
  parameter ArmExo.Units.Length L2(min = 0) = 0.35 "Length of link 2";
  parameter ArmExo.Units.Length lc2(min = 0) = 0.175 "Joint 2 to centre of mass of link 2";
  parameter ArmExo.Units.Inertia I2(min = 0) = 0.0102 "Inertia of link 2 about its centre of mass";
  parameter ArmExo.Units.Inertia Jm[2](each min = 0) = {0.010, 0.010} "Reflected motor/transmission inertia";
  parameter Real Jm_on_link[2] = {1, 1} "1: Jm moves with the link (rigid transmission), 0: with the motor";
  parameter ArmExo.Units.DimensionlessRatio scale(min = 0) = 1 "Scale of a1, a2, a3 (inertia mismatch)";
  parameter ArmExo.Units.Angle beta = 0 "Tilt of the plane from horizontal (gravity)";
  parameter ArmExo.Units.Angle q0[2] = {1.0944, 1.3484} "Posture (absolute angles)";
  parameter ArmExo.Units.Acceleration g_n = 9.81 "Gravity of Earth";
  final parameter ArmExo.Units.Inertia a1 = scale*(I1 + m1*lc1^2 + I2 + m2*(L1^2 + lc2^2));
  final parameter ArmExo.Units.Inertia a2 = scale*(I2 + m2*lc2^2);
  final parameter ArmExo.Units.Inertia a3 = scale*m2*L1*lc2;
  final parameter Boolean tilted = beta <> 0 "Gravity acts (a run-time switch: no cosines of q1 when level)";
  final parameter ArmExo.Units.Acceleration g_tilt = g_n*sin(beta) "In-plane gravity";
  input ArmExo.Units.Angle theta[2] "Link angles, deviation from the posture";
  input ArmExo.Units.AngularVelocity w[2] "Link velocities";
  output ArmExo.Units.Inertia M[2, 2] "Mass matrix M_r(q) (with Jm where it moves with the link)";
  output ArmExo.Units.Torque c[2] "Coriolis and centrifugal torques c_r(q, q')";
  output ArmExo.Units.Torque G[2] "Gravity torques";
protected
  ArmExo.Units.Angle q[2] = q0 + theta "Absolute angles";
equation
  M = [a1 + 2*a3*cos(q[2]) + Jm_on_link[1]*Jm[1], a2 + a3*cos(q[2]);
       a2 + a3*cos(q[2]), a2 + Jm_on_link[2]*Jm[2]];
  c = a3*sin(q[2])*{-(2*w[1]*w[2] + w[2]^2), w[1]^2};
  G[2] = if tilted then g_tilt*m2*lc2*cos(q[1] + q[2]) else 0;
  G[1] = if tilted then g_tilt*(m1*lc1 + m2*L1)*cos(q[1]) + G[2] else 0;
  annotation (Documentation(info = "<html>
<p>Link-side dynamics of the 2-link planar exoskeleton (docs/spec/reference.md section 3):</p>
<pre>
  a1 = s (I1 + m1 lc1^2 + I2 + m2 (L1^2 + lc2^2)),  a2 = s (I2 + m2 lc2^2),  a3 = s m2 L1 lc2
  M_r(q) = [a1 + 2 a3 cos q2 + Jm1, a2 + a3 cos q2; a2 + a3 cos q2, a2 + Jm2]
  c_r    = a3 sin q2 [-(2 q1' q2' + q2'^2), q1'^2]
  G(q)   = g sin(beta) [(m1 lc1 + m2 L1) cos q1 + m2 lc2 cos(q1 + q2), m2 lc2 cos(q1 + q2)]
  M_r(q) theta'' + c_r + G = sum of the joint torques on the links
</pre>
<p>s scales a1..a3 (inertia mismatch, not Jm); beta tilts the plane about the base x axis
(gravity acts along -y of the plane, nominal masses). With a compliant transmission Jm
moves with the motor (Jm_on_link = 0).</p>
</html>"));
end PlanarExoskeleton2DOF;
