within ArmExo.Components;
model PlanarExoskeletonNDOF "Serial n-link planar exoskeleton: mass matrix, Coriolis/centrifugal and gravity torques"
  extends ArmExo.Icons.Block;
  parameter Integer n = 3 "Number of links";
  parameter ArmExo.Units.Mass m[n] "Link masses";
  parameter ArmExo.Units.Length L[n] "Link lengths";
  parameter ArmExo.Units.Length lc[n] "Joint i to centre of mass of link i";
  parameter ArmExo.Units.Inertia I[n] "Link inertias about their centres of mass";
  parameter ArmExo.Units.Inertia Jm[n] "Reflected motor/transmission inertias";
  parameter Real Jm_on_link[n] = fill(1, n) "1: Jm moves with the link (rigid transmission), 0: with the motor";
  parameter ArmExo.Units.DimensionlessRatio scale(min = 0) = 1 "Scale of d (inertia mismatch)";
  parameter ArmExo.Units.Angle beta = 0 "Tilt of the plane from horizontal (gravity)";
  parameter ArmExo.Units.Angle q0[n] "Posture (q1 absolute, q2..qn relative to the previous link)";
  parameter ArmExo.Units.Acceleration g_n = 9.81 "Gravity of Earth";
  final parameter ArmExo.Units.Mass tail[n] = {sum({if i > a then m[i] else 0 for i in 1:n}) for a in 1:n}
    "Mass of the links beyond link a";
  final parameter ArmExo.Units.Inertia d[n, n] = {{if a == b then scale*(I[a] + m[a]*lc[a]^2 + L[a]^2*tail[a])
    else if a < b then scale*L[a]*(m[b]*lc[b] + L[b]*tail[b]) else scale*L[b]*(m[a]*lc[a] + L[a]*tail[a])
    for b in 1:n} for a in 1:n} "Inertia coefficients in absolute link angles";
  final parameter Real S[n, n] = {{if a >= j then 1 else 0 for j in 1:n} for a in 1:n}
    "Absolute link angles phi = S q";
  input ArmExo.Units.Angle theta[n] "Link angles, deviation from the posture";
  input ArmExo.Units.AngularVelocity w[n] "Link velocities";
  output ArmExo.Units.Inertia M[n, n] "Mass matrix M_r(q) (with Jm where it moves with the link)";
  output ArmExo.Units.Torque c[n] "Coriolis and centrifugal torques c_r(q, q')";
  output ArmExo.Units.Torque G[n] "Gravity torques";
protected
  ArmExo.Units.Angle phi[n] "Absolute link angles";
  ArmExo.Units.AngularVelocity phid[n] "Absolute link velocities";
equation
  phi = S*(q0 + theta);
  phid = S*w;
  M = transpose(S)*{{d[a, b]*cos(phi[a] - phi[b]) for b in 1:n} for a in 1:n}*S
      + diagonal({Jm_on_link[j]*Jm[j] for j in 1:n});
  c = transpose(S)*{sum({d[a, b]*sin(phi[a] - phi[b])*phid[b]^2 for b in 1:n}) for a in 1:n};
  G = transpose(S)*{g_n*sin(beta)*(m[a]*lc[a] + L[a]*tail[a])*cos(phi[a]) for a in 1:n};
  annotation (Documentation(info = "<html>
<p>Link-side dynamics of an n-link planar exoskeleton (docs/spec/reference-3dof.md for
n = 3), from the kinetic energy in absolute link angles phi = S q:</p>
<pre>
  T = 1/2 phi'^T D(phi) phi',  D_ab = d_ab cos(phi_a - phi_b)
  d_aa = s (I_a + m_a lc_a^2 + L_a^2 sum_{i>a} m_i),  d_ab = s L_a (m_b lc_b + L_b sum_{i>b} m_i)  (a &lt; b)
  M_r(q) = S^T D S + diag(Jm),  c_r = S^T [sum_b d_ab sin(phi_a - phi_b) phi_b'^2]
  G = S^T [g sin(beta) (m_a lc_a + L_a sum_{i>a} m_i) cos phi_a]
</pre>
<p>For n = 2 these are PlanarExoskeleton2DOF's a1 = d11 + d22, a2 = d22, a3 = d12; for
n = 3 reference-3dof.md's M_r entries and Christoffel-symbol Coriolis torques.</p>
</html>"));
end PlanarExoskeletonNDOF;
