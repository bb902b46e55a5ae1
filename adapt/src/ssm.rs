//! (issue 4: separation monitoring and QP speed scaling; being written)
