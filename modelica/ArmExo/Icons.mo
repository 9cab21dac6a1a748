within ArmExo;
package Icons "Icons (empty: graphics are not used)"

  partial package Package "Icon for a package"
  end Package;

  partial model Block "Icon for a block-like model"
  end Block;
end Icons;
