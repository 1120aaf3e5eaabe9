//! The two engines' migrations give the same schema: the same tables, and in each the same
//! columns in the same order with the same kind of type, nullability, default and primary
//! key, and the same indexes. Read from SQLite's `pragma_table_info` / `pragma_index_list`
//! and PostgreSQL's `information_schema` / `pg_indexes`, after every migration ran on a
//! fresh database of each (the server of `$CUTLAB_TEST_POSTGRES`; CI starts one).

use std::collections::BTreeMap;

use cutlab_assessor::Store;
use cutlab_assessor::on_db;
use cutlab_assessor::store::test_postgres;
use cutlab_assessor::store::{POSTGRES_MIGRATOR, SQLITE_MIGRATOR};

/// A column as both engines can describe it.
#[derive(Debug, Clone, PartialEq, Eq)]
struct Column {
    name: String,
    /// `integer`, `real`, `text` or `boolean`.
    kind: &'static str,
    not_null: bool,
    has_default: bool,
    primary_key: bool,
}

/// Table name -> columns in order, plus the names of the indexes that are not keys.
type Schema = (BTreeMap<String, Vec<Column>>, Vec<String>);

fn kind(declared: &str) -> &'static str {
    let t = declared.to_ascii_lowercase();
    if t.contains("int") {
        "integer"
    } else if t.contains("double") || t.contains("real") || t.contains("float") {
        "real"
    } else if t.contains("bool") {
        "boolean"
    } else if t.contains("text") || t.contains("char") {
        "text"
    } else {
        panic!("a column type neither engine should see here: {declared}")
    }
}

async fn sqlite_schema(store: &Store) -> Schema {
    on_db!(store.db(), pool => {
        let tables: Vec<String> = sqlx::query_scalar(
            "SELECT name FROM sqlite_master WHERE type = 'table' AND name NOT LIKE 'sqlite_%' AND name <> '_sqlx_migrations' ORDER BY name",
        )
        .fetch_all(pool)
        .await
        .expect("tables");
        let mut out = BTreeMap::new();
        let mut indexes = Vec::new();
        for t in tables {
            let cols: Vec<(String, String, bool, Option<String>, i64)> = sqlx::query_as(
                "SELECT name, type, \"notnull\", dflt_value, pk FROM pragma_table_info($1) ORDER BY cid",
            )
            .bind(&t)
            .fetch_all(pool)
            .await
            .expect("columns");
            let key_columns = cols.iter().filter(|c| c.4 > 0).count();
            out.insert(
                t.clone(),
                cols.into_iter()
                    .map(|(name, ty, not_null, default, pk)| Column {
                        name,
                        kind: kind(&ty),
                        // SQLite lets a primary key be NULL unless told; PostgreSQL never does
                        not_null: not_null || pk > 0,
                        // a lone `INTEGER PRIMARY KEY` is auto-numbered: an identity column
                        has_default: default.is_some()
                            || (pk > 0 && key_columns == 1 && ty == "INTEGER"),
                        primary_key: pk > 0,
                    })
                    .collect(),
            );
            let named: Vec<String> = sqlx::query_scalar(
                "SELECT name FROM pragma_index_list($1) WHERE origin = 'c' ORDER BY name",
            )
            .bind(&t)
            .fetch_all(pool)
            .await
            .expect("indexes");
            indexes.extend(named);
        }
        indexes.sort();
        (out, indexes)
    })
}

async fn postgres_schema(store: &Store) -> Schema {
    on_db!(store.db(), pool => {
        let cols: Vec<(String, String, String, bool, bool, bool)> = sqlx::query_as(
            "SELECT c.table_name::text, c.column_name::text, c.data_type::text, c.is_nullable = 'NO', \
                    c.column_default IS NOT NULL OR c.is_identity = 'YES', \
                    EXISTS (SELECT 1 FROM information_schema.table_constraints k \
                            JOIN information_schema.key_column_usage u \
                              ON u.constraint_name = k.constraint_name AND u.table_name = k.table_name \
                            WHERE k.constraint_type = 'PRIMARY KEY' AND k.table_name = c.table_name \
                              AND u.column_name = c.column_name) \
             FROM information_schema.columns c \
             WHERE c.table_schema = current_schema() AND c.table_name <> '_sqlx_migrations' \
             ORDER BY c.table_name, c.ordinal_position",
        )
        .fetch_all(pool)
        .await
        .expect("columns");
        let mut out: BTreeMap<String, Vec<Column>> = BTreeMap::new();
        for (table, name, ty, not_null, has_default, primary_key) in cols {
            out.entry(table).or_default().push(Column {
                name,
                kind: kind(&ty),
                not_null,
                has_default,
                primary_key,
            });
        }
        let indexes: Vec<String> = sqlx::query_scalar(
            "SELECT i.indexname::text FROM pg_indexes i \
             WHERE i.schemaname = current_schema() AND i.tablename <> '_sqlx_migrations' \
               AND NOT EXISTS (SELECT 1 FROM pg_constraint k WHERE k.conname = i.indexname) \
             ORDER BY 1",
        )
        .fetch_all(pool)
        .await
        .expect("indexes");
        (out, indexes)
    })
}

#[tokio::test]
async fn both_engines_have_the_same_schema() {
    let dir = tempfile::tempdir().expect("temporary folder");
    let sqlite = Store::open(&dir.path().join("cutlab.db"))
        .await
        .expect("sqlite");
    let (sqlite_tables, sqlite_indexes) = sqlite_schema(&sqlite).await;
    assert!(sqlite_tables.len() >= 14, "{:?}", sqlite_tables.keys());
    assert!(sqlite_indexes.len() >= 5, "{sqlite_indexes:?}");
    let Some(at) = test_postgres("cutlab_schema_test").await else {
        return;
    };
    let postgres = Store::open(&at).await.expect("postgres");
    let (pg_tables, pg_indexes) = postgres_schema(&postgres).await;
    assert_eq!(
        sqlite_tables.keys().collect::<Vec<_>>(),
        pg_tables.keys().collect::<Vec<_>>(),
        "tables"
    );
    for (table, columns) in &sqlite_tables {
        assert_eq!(columns, &pg_tables[table], "columns of {table}");
    }
    assert_eq!(sqlite_indexes, pg_indexes, "indexes");
}

#[test]
fn both_engines_have_the_same_migrations() {
    let versions = |m: &sqlx::migrate::Migrator| {
        m.iter()
            .map(|m| (m.version, m.description.to_string()))
            .collect::<Vec<_>>()
    };
    assert_eq!(versions(&SQLITE_MIGRATOR), versions(&POSTGRES_MIGRATOR));
}
