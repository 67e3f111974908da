//! The worker's integration tests, one binary (see STYLE: link time).

mod integration {
    mod gpu;
    mod preview;
    mod trace;
}
