// The cell hardware implementations as pluginlib plugins (hardware_plugins.xml): the airbag
// node loads one by its ~hardware/plugin name. A new driver (EtherCAT, CAN) is one more class
// here or in its own package, exported the same way (doc/real_bed.md).
#include <pluginlib/class_list_macros.hpp>

#include "nursing_bed/core/hardware/modbus_tcp_hardware.h"
#include "nursing_bed/core/hardware/simulated_cell_hardware.h"

PLUGINLIB_EXPORT_CLASS(nursing_bed::SimulatedCellHardware, nursing_bed::CellHardware)
PLUGINLIB_EXPORT_CLASS(nursing_bed::ModbusTcpCellHardware, nursing_bed::CellHardware)
