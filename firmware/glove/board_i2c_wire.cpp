/* handrig glove firmware: I2C through the Arduino Wire library (every core).
 * A timeout bounds every transfer, so a missing, unplugged or hung IMU costs at
 * most a millisecond per attempt and never stalls the frames. */
#include <Arduino.h>
#include <Wire.h>

#include "board.h"

void board_i2c_begin(void) {
    Wire.begin();
    Wire.setClock(400000);
#if defined(ARDUINO_ARCH_AVR) || defined(WIRE_HAS_TIMEOUT) /* Debian's AVR core has it */
    Wire.setWireTimeout(1000 /* us */, true /* reset the TWI unit on a timeout */);
#endif
}

uint8_t board_i2c_write(uint8_t addr, uint8_t reg, uint8_t value) {
    Wire.beginTransmission(addr);
    Wire.write(reg);
    Wire.write(value);
    return Wire.endTransmission() == 0;
}

uint8_t board_i2c_read(uint8_t addr, uint8_t reg, uint8_t *buf, uint8_t n) {
    Wire.beginTransmission(addr);
    Wire.write(reg);
    if (Wire.endTransmission(false) != 0) return 0; /* repeated start follows */
    if (Wire.requestFrom(addr, n) != n) return 0;
    for (uint8_t i = 0; i < n; i++) buf[i] = (uint8_t)Wire.read();
    return 1;
}
