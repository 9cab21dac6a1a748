within ArmExo.Interfaces;
partial model PartialVectorBlock "n inputs u, n outputs y"
  extends ArmExo.Icons.Block;
  parameter Integer n = 2 "Number of joints";
  input Real u[n] "Input signal";
  output Real y[n] "Output signal";
  annotation (Documentation(info = "<html><p>Base of vector blocks with n inputs u and n outputs y (one channel per joint).</p></html>"));
end PartialVectorBlock;
