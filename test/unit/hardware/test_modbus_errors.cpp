// Which libmodbus errors the modbus_tcp hardware retries next cycle and which take the link
// down at once (the exchanges themselves: test/unit/rig/test_modbus_loopback.cpp).
#include <gtest/gtest.h>

#include <cerrno>

#include <modbus/modbus.h>

#include "nursing_bed/core/hardware/modbus_tcp_hardware.h"

namespace nb = nursing_bed;

TEST(TransientModbusError, TimeoutsAndBadRepliesAreRetriedAClosedConnectionIsNot) {
  for (int e : {ETIMEDOUT, EMBBADDATA, EMBBADEXC, EMBXSBUSY, EMBXGTAR})
    EXPECT_TRUE(nb::transientModbusError(e)) << modbus_strerror(e);
  for (int e : {ECONNRESET, ECONNREFUSED, EPIPE, EBADF, ENOTCONN, EMBXILADD, EMBXILFUN, EMBXSFAIL, 0})
    EXPECT_FALSE(nb::transientModbusError(e)) << modbus_strerror(e);
}
