"""The hand: kinematic model, procedural mesh, colour glove, URDF, pose collections."""
