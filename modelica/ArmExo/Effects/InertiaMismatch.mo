within ArmExo.Effects;
model InertiaMismatch "The real robot's a1, a2, a3 scaled"
  parameter ArmExo.Units.DimensionlessRatio scale(min = 0) = 1 "Scale of a1, a2, a3, not Jm (1: off)";
  annotation (Documentation(info = "<html>
<p>Applied in <a href=\"modelica://ArmExo.Components.PlanarExoskeleton2DOF\">PlanarExoskeleton2DOF</a>.</p>
</html>"));
end InertiaMismatch;
