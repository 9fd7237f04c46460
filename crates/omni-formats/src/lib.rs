//! Every omniscan file and stream record type, versioned; PLY; atomic writes.
