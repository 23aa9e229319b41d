//! Tests that hold the models to the papers' tables and figures live in this folder, one file
//! per paper; shared helpers go here.
