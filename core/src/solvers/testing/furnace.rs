//! White furnace and energy balance, written once and run over every solver.
