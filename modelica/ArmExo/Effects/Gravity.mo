within ArmExo.Effects;
model Gravity "Tilt of the robot's plane: gravity torques on the links"
  parameter ArmExo.Units.Angle_deg tilt_deg = 0 "Tilt from horizontal about the base x axis (0: off)";
  final parameter ArmExo.Units.Angle beta = tilt_deg*3.141592653589793/180 "Tilt";
  annotation (Documentation(info = "<html>
<p>g sin(beta) acts along -y of the plane on the robot links (nominal masses), not on the
linearised arm; the torques are computed by
<a href=\"modelica://ArmExo.Components.PlanarExoskeleton2DOF\">PlanarExoskeleton2DOF</a>.</p>
</html>"));
end Gravity;
