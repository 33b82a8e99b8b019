namespace irradcast {}
