"""What crosses the instrument boundary: Modbus TCP/RTU, NMEA-style serial lines, output field table."""
